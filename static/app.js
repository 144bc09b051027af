// facesvg web UI: drag-and-drop upload, live job progress, result player. No framework; pages work without it.
"use strict";

// A drop zone (the face's, the take's) puts a dropped file into its file input, as choosing one would.
function setupDrop(zone, input, label) {
  if (!zone || !input) return;
  const show = () => { if (label) label.textContent = input.files.length ? input.files[0].name : ""; };
  input.addEventListener("change", show);
  ["dragenter", "dragover"].forEach((t) => zone.addEventListener(t, (e) => {
    e.preventDefault(); zone.classList.add("dragover");
  }));
  ["dragleave", "drop"].forEach((t) => zone.addEventListener(t, () => zone.classList.remove("dragover")));
  zone.addEventListener("drop", (e) => {
    e.preventDefault();
    e.stopPropagation();
    if (e.dataTransfer && e.dataTransfer.files.length) {
      input.files = e.dataTransfer.files;
      input.dispatchEvent(new Event("change", { bubbles: true })); // the name and the size check, as on choosing
      document.getElementById("convert").focus();
    }
  });
}

function setupDrops() {
  setupDrop(document.querySelector("[data-drop]"), document.getElementById("file"),
    document.getElementById("file-name"));
  setupDrop(document.querySelector("[data-drop-take]"), document.getElementById("file-weights"),
    document.getElementById("take-name"));
  // A file dropped outside the zones must not navigate away from the form.
  window.addEventListener("dragover", (e) => e.preventDefault());
  window.addEventListener("drop", (e) => e.preventDefault());
}

const MAX_POLL_FAILURES = 5; // about 9 s of backing off

function setupProgress() {
  const box = document.querySelector("[data-status-url]");
  if (!box) return;
  const url = box.dataset.statusUrl;
  const bar = document.getElementById("progress");
  const stage = document.getElementById("stage");
  const percent = document.getElementById("percent");
  const state = document.getElementById("job-state");
  let delay = 300;
  let failures = 0;
  function lostTouch() {
    state.textContent = "unknown";
    state.className = "state state-error";
    stage.textContent = "no readable answer from the server";
    const note = document.getElementById("poll-error");
    if (note) note.hidden = false;
  }
  async function poll() {
    try {
      const r = await fetch(url, { headers: { Accept: "application/json" }, cache: "no-store" });
      if (r.status === 404) { stage.textContent = "this job was deleted"; return; }
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const job = await r.json(); // throws on an answer that is not JSON
      if (!job || typeof job.state !== "string") throw new Error("not a job");
      failures = 0;
      bar.value = job.percent;
      percent.textContent = job.percent;
      stage.textContent = job.stage;
      showStanding(job);
      state.textContent = job.state;
      state.className = "state state-" + job.state;
      if (["done", "failed", "cancelled"].includes(job.state)) {
        if (job.state === "done") { bar.value = 100; percent.textContent = "100"; stage.textContent = "done"; }
        setTimeout(() => window.location.reload(), 400); // let the full bar show before the result replaces it
        return;
      }
      delay = 400;
    } catch (err) {
      // Server busy or restarting: back off and try again; after several unreadable answers in a row, say so
      // instead of showing the last progress for ever.
      failures += 1;
      if (failures >= MAX_POLL_FAILURES) { lostTouch(); return; }
      delay = Math.min(delay * 2, 5000);
    }
    setTimeout(poll, delay);
  }
  poll();
}

// Queue place and time left, as the API reports them (the page shows the same at load without JS).
function showStanding(job) {
  const place = document.getElementById("queue-position");
  const eta = document.getElementById("eta");
  if (place) place.textContent = job.queue_position ? `Place in the queue: ${job.queue_position}` : "";
  if (eta) {
    const s = job.eta_seconds;
    if (s === null || s === undefined) eta.textContent = job.estimating ? "Time left: estimating…" : "";
    else eta.textContent = `Done in about ${s < 90 ? Math.max(Math.round(s), 1) + " s" : Math.round(s / 60) + " min"}`;
  }
}

// Preset buttons set their fields; a refill (the options of a failed job, "Try again") fills the whole form.
function setField(form, name, value) {
  const fields = form.querySelectorAll(`[name="${name}"]`);
  fields.forEach((el) => {
    if (el.type === "checkbox") el.checked = value === true || value === "1" || value === 1;
    else if (el.type === "hidden" || el.type === "file") return;
    else el.value = value === null || value === undefined ? "" : String(value);
  });
}

// A size as the server words it: "1.5 MB", "64 KB".
function sizeText(n) {
  const mb = n / 1048576;
  if (n >= 1048576) return Number.isInteger(mb) || mb >= 100 ? `${Math.round(mb)} MB` : `${mb.toFixed(1)} MB`;
  return n >= 1024 ? `${Math.max(Math.round(n / 1024), 1)} KB` : `${n} bytes`;
}

// The server refuses a body over its limit (413); say so before sending, naming the file, with the same limit.
function setupSizeCheck(form) {
  const limit = parseInt(form.dataset.maxBytes, 10);
  const box = document.getElementById("size-error");
  if (!limit || !box) return;
  const limitText = form.dataset.maxText || sizeText(limit);
  const advice = "Reduce it (fewer frames, a .glb with meshopt compression) or ask the administrator to raise "
    + "the limit.";
  function check() {
    const files = [];
    form.querySelectorAll('input[type="file"]').forEach((input) => files.push(...input.files));
    const big = files.filter((f) => f.size > limit);
    const total = files.reduce((sum, f) => sum + f.size, 0);
    let message = "";
    if (big.length) {
      message = big.map((f) => `“${f.name}” is ${sizeText(f.size)}, over the ${limitText} upload limit.`).join(" ")
        + " " + advice;
    } else if (total > limit) {
      message = `The chosen files are ${sizeText(total)} together, over the ${limitText} upload limit. ${advice}`;
    }
    box.textContent = message;
    box.hidden = !message;
    return !message;
  }
  form.addEventListener("change", (e) => { if (e.target.type === "file") check(); });
  form.addEventListener("submit", (e) => {
    if (!check()) { e.preventDefault(); box.scrollIntoView({ block: "center" }); }
  });
}

function setupForm() {
  const form = document.getElementById("upload-form");
  if (!form) return;
  setupSizeCheck(form);
  document.querySelectorAll("[data-preset]").forEach((button) => {
    button.addEventListener("click", () => {
      const values = JSON.parse(button.dataset.preset);
      Object.entries(values).forEach(([k, v]) => setField(form, k, v));
      button.setAttribute("aria-pressed", "true");
    });
  });
  const refill = document.getElementById("refill");
  if (refill) {
    const values = JSON.parse(refill.textContent || "{}");
    Object.entries(values).forEach(([k, v]) => setField(form, k, v));
  }
}

const INSPECT_MAX_BYTES = 64 * 1048576; // larger faces are not sent twice just for suggestions

// What a chosen file is (the server reads it: /api/v1/inspect): a face's clips, parts and nodes become the text
// options' suggestions, and the page says what the face can be driven by; a take is named with its layout.
function setupInspect() {
  const form = document.getElementById("upload-form");
  if (!form || !form.dataset.inspectUrl) return;
  const face = document.getElementById("file");
  const take = document.getElementById("file-weights");
  const faceInfo = document.getElementById("face-info");
  const takeInfo = document.getElementById("take-info");
  let asked = 0;
  // A file over the upload limit is never sent (the server would refuse it with a 413): the form says so instead.
  const uploadLimit = parseInt(form.dataset.maxBytes, 10) || Infinity;
  const sendable = (file) => file && file.size <= Math.min(INSPECT_MAX_BYTES, uploadLimit);
  async function inspect(file, role) {
    const body = new FormData();
    body.append("file", file, file.name);
    if (role) body.append("role", role);
    const r = await fetch(form.dataset.inspectUrl, { method: "POST", body, headers: { Accept: "application/json" } });
    let answer = null;
    try { answer = await r.json(); } catch (err) { answer = null; }
    if (!r.ok) throw new Error((answer && answer.error) || `the server could not read it (HTTP ${r.status})`);
    return answer;
  }
  function say(box, text, bad) {
    if (!box) return;
    box.textContent = text;
    box.classList.toggle("bad", Boolean(bad));
  }
  function fill(name, values) {
    const input = form.querySelector(`input[data-suggest="${name}"]`);
    const list = input && document.getElementById(input.getAttribute("list"));
    if (!list) return;
    list.querySelectorAll("option[data-from-file]").forEach((o) => o.remove());
    values.forEach(([value, label]) => {
      const option = document.createElement("option");
      option.value = value;
      if (label) option.label = label;
      option.dataset.fromFile = "1";
      list.appendChild(option);
    });
    input.dataset.suggestions = String(values.length);
  }
  function takeText(t) {
    return `${t.layout} take: ${t.frames} frames at ${t.fps} fps (${Number(t.duration).toFixed(1)} s), `
      + `${t.names} weights.`;
  }
  function faceText(f) {
    const parts = [];
    const clips = f.animations || [];
    if (clips.length) {
      parts.push(`${clips.length} clip${clips.length > 1 ? "s" : ""}: `
        + clips.map((c) => c.name || `#${c.index}`).join(", ") + ".");
    }
    if (f.morph_targets) {
      const still = !clips.length && f.frames === 1;
      parts.push(`${f.morph_targets} morph targets` + (still
        ? ", nothing animates them: add a take to drive them, or the result is a still (one frame)."
        : ": a take can drive them."));
    }
    return parts.join(" ");
  }
  if (face) face.addEventListener("change", async () => {
    const file = face.files[0];
    const ticket = ++asked;
    fill("animations", []); fill("frame_on", []);
    say(faceInfo, "");
    if (!sendable(file)) return;
    say(faceInfo, "Reading the face…");
    try {
      const info = await inspect(file);
      if (ticket !== asked) return;
      if (info.kind === "take") { // a take dropped on the face: it belongs beside it
        if (take) {
          take.files = face.files;
          take.dispatchEvent(new Event("change", { bubbles: true }));
          face.value = "";
          face.dispatchEvent(new Event("change", { bubbles: true }));
          say(faceInfo, `“${file.name}” is a take, not a face: it was put in “A take”. Choose the face it drives.`);
        } else {
          say(faceInfo, `“${file.name}” is a take, not a face.`, true);
        }
        return;
      }
      fill("animations", (info.animations || []).map((c) => [c.name || String(c.index),
        c.name ? `clip ${c.index}` : "unnamed clip"]));
      fill("frame_on", (info.frame_on || []).map((n) => [n, ""]));
      say(faceInfo, faceText(info));
    } catch (err) {
      if (ticket === asked) say(faceInfo, err.message, true);
    }
  });
  if (take) take.addEventListener("change", async () => {
    const file = take.files[0];
    say(takeInfo, "");
    if (!sendable(file)) return;
    try {
      const info = await inspect(file, "take");
      if (info.kind !== "take") say(takeInfo, `“${file.name}” is a face, not a take: put it in “A face”.`, true);
      else say(takeInfo, takeText(info));
    } catch (err) {
      say(takeInfo, err.message, true);
    }
  });
}

// A large result draws half-finished for seconds: say it is loading until its load event.
function setupLoading() {
  const note = document.getElementById("view-loading");
  const view = document.querySelector("#stage object, #stage iframe");
  if (!note || !view) return;
  const done = () => { note.hidden = true; };
  view.addEventListener("load", done);
  view.addEventListener("error", () => { note.textContent = "The result could not be shown; download it below."; });
  const doc = view.contentDocument;
  if (doc && doc.readyState === "complete" && doc.URL !== "about:blank") done();
}

// The playing time (s) of an output's own player in a frame, from the API it exposes (the WebGL player's
// facesvgPlayer, the 2D package's fap2dPlayer, the puppet's puppet), or null while it has none.
function playerTime(win) {
  if (!win) return null;
  for (const name of ["facesvgPlayer", "fap2dPlayer", "puppet"]) {
    const p = win[name];
    if (!p) continue;
    if (typeof p.time === "number" && Number.isFinite(p.time)) return p.time;
    if (typeof p.frame === "number" && p.fps > 0) return p.frame / p.fps;
  }
  return null;
}

// One player per result: an output with its own player (HTML, 2D package) keeps its controls; the frame is
// sized to the player so they are never cut off, and the 3D prerender follows the player's clock.
function setupFramedPlayer() {
  const player = document.getElementById("player");
  const frame = document.querySelector("#stage iframe");
  if (!player || !frame || player.dataset.viewer !== "frame") return;
  const fps = parseFloat(player.dataset.fps) || 30;
  const frames = parseInt(player.dataset.frames, 10) || 1;
  const previews = JSON.parse(player.dataset.previews || "[]");
  const base = player.dataset.previewBase;
  const img = document.getElementById("prerender");
  const prLabel = document.getElementById("prerender-label");
  previews.forEach((k) => { const i = new Image(); i.src = base + k; });
  let shown = previews.length ? previews[0] : -1;
  function fit() {
    const doc = frame.contentDocument;
    if (!doc || !doc.documentElement) return;
    // The body's height, not the document's: that is at least the frame's own, so it could only grow.
    const h = doc.body ? Math.ceil(doc.body.getBoundingClientRect().height) : 0;
    if (h > 0) frame.style.height = `${h}px`;
  }
  function follow() {
    const t = playerTime(frame.contentWindow);
    if (t !== null && img && previews.length) {
      const k = Math.min(Math.max(Math.round(t * fps), 0), frames - 1);
      let best = previews[0];
      for (const p of previews) if (Math.abs(p - k) < Math.abs(best - k)) best = p;
      if (best !== shown) { img.src = base + best; shown = best; }
      prLabel.textContent = best === k ? `frame ${best}` : `frame ${best} (nearest rendered to ${k})`;
      player.dataset.followed = String(k);
    }
    requestAnimationFrame(follow);
  }
  function attach() {
    const body = frame.contentDocument && frame.contentDocument.body;
    if (body) body.style.textAlign = "center"; // a player narrower than the frame sits in its middle
    fit();
    const doc = frame.contentDocument;
    if (doc && doc.body && window.ResizeObserver) new ResizeObserver(fit).observe(doc.body);
  }
  frame.addEventListener("load", attach);
  if (frame.contentDocument && frame.contentDocument.readyState === "complete") attach();
  window.addEventListener("resize", fit);
  requestAnimationFrame(follow);
}

function setupPlayer() {
  const player = document.getElementById("player");
  if (!player || !document.getElementById("play")) return; // no player, or a still: nothing to drive
  const fps = parseFloat(player.dataset.fps) || 30;
  const frames = parseInt(player.dataset.frames, 10) || 1;
  const previews = JSON.parse(player.dataset.previews || "[]");
  const base = player.dataset.previewBase;
  const obj = document.getElementById("svg-view");
  const img = document.getElementById("prerender");
  const slider = document.getElementById("frame-slider");
  const label = document.getElementById("frame-label");
  const prLabel = document.getElementById("prerender-label");
  const play = document.getElementById("play");
  const duration = frames / fps;
  let svg = null;
  let playing = false;
  let shown = -1;
  let t0 = 0, wall0 = 0;

  // Preload the prerenders so scrubbing is instant.
  previews.forEach((k) => { const i = new Image(); i.src = base + k; });

  function nearestPreview(k) {
    let best = previews[0];
    for (const p of previews) if (Math.abs(p - k) < Math.abs(best - k)) best = p;
    return best;
  }
  function showFrame(k) {
    slider.value = k;
    label.textContent = `frame ${k} / ${frames} · ${(k / fps).toFixed(2)} s`;
    if (img && previews.length) {
      const p = nearestPreview(k);
      if (p !== shown) { img.src = base + p; shown = p; }
      prLabel.textContent = p === k ? `frame ${p}` : `frame ${p} (nearest rendered)`;
    }
  }
  function seek(k) {
    if (svg && svg.setCurrentTime) { svg.pauseAnimations(); svg.setCurrentTime(k / fps); }
    showFrame(k);
  }
  function tick() {
    if (!playing) return;
    let t;
    if (svg && svg.getCurrentTime) t = svg.getCurrentTime();
    else t = t0 + (performance.now() - wall0) / 1000;
    const k = Math.floor(((t % duration) + duration) % duration * fps) % frames;
    showFrame(k);
    requestAnimationFrame(tick);
  }
  function setPlaying(on) {
    playing = on;
    play.textContent = on ? "Pause" : "Play";
    play.setAttribute("aria-pressed", String(on));
    const k = parseInt(slider.value, 10) || 0;
    if (on) {
      t0 = k / fps; wall0 = performance.now();
      if (svg && svg.setCurrentTime) { svg.setCurrentTime(k / fps); svg.unpauseAnimations(); }
      requestAnimationFrame(tick);
    } else {
      seek(k);
    }
  }
  play.addEventListener("click", () => setPlaying(!playing));
  slider.addEventListener("input", () => { if (playing) setPlaying(false); seek(parseInt(slider.value, 10)); });
  player.addEventListener("keydown", (e) => {
    if (e.key === " " && e.target === slider) { e.preventDefault(); setPlaying(!playing); }
  });
  function attach() {
    const doc = obj && obj.contentDocument;
    svg = doc && doc.documentElement && doc.documentElement.setCurrentTime ? doc.documentElement : null;
    seek(parseInt(slider.value, 10) || 0);
  }
  if (obj) {
    obj.addEventListener("load", attach);
    if (obj.contentDocument && obj.contentDocument.readyState === "complete") attach();
  } else {
    showFrame(0);
  }
}

document.addEventListener("DOMContentLoaded", () => {
  setupDrops(); setupForm(); setupInspect(); setupProgress(); setupLoading(); setupPlayer(); setupFramedPlayer();
});
