// facesvg web UI: drag-and-drop upload, live job progress, result player. No framework; pages work without it.
"use strict";

function setupDrop() {
  const drop = document.querySelector("[data-drop]");
  const input = document.getElementById("file");
  const label = document.getElementById("file-name");
  if (!drop || !input) return;
  const show = () => { label.textContent = input.files.length ? input.files[0].name : ""; };
  input.addEventListener("change", show);
  ["dragenter", "dragover"].forEach((t) => drop.addEventListener(t, (e) => {
    e.preventDefault(); drop.classList.add("dragover");
  }));
  ["dragleave", "drop"].forEach((t) => drop.addEventListener(t, () => drop.classList.remove("dragover")));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    if (e.dataTransfer && e.dataTransfer.files.length) {
      input.files = e.dataTransfer.files;
      input.dispatchEvent(new Event("change", { bubbles: true })); // the name and the size check, as on choosing
      document.getElementById("convert").focus();
    }
  });
  // A file dropped outside the zone must not navigate away from the form.
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
    eta.textContent = s === null || s === undefined ? ""
      : `Done in about ${s < 90 ? Math.max(Math.round(s), 1) + " s" : Math.round(s / 60) + " min"}`;
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

document.addEventListener("DOMContentLoaded", () => { setupDrop(); setupForm(); setupProgress(); setupPlayer(); });
