// facesvg live page (templates/live.html): connects to the feed the page names, shows the connection's state, the
// packets a second, the last packet's age and the strongest weights, and drives the puppet in the frame through its
// window.puppet API (same origin). A feed that is not up yet, or goes away, is tried again every few seconds.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const box = $("live");
  if (!box) return;
  const url = box.dataset.feed;
  const QUIET_MS = 1000 * (Number(box.dataset.quiet) || 2);
  const RETRY_MS = 1000 * (Number(box.dataset.retry) || 2);
  const BARS = 8;  // weights shown
  const DEG = 180 / Math.PI;
  const frame = $("live-puppet");

  let socket = null;
  let attempts = 0;
  let everOpen = false;  // once a feed was up, a failed retry keeps showing why it closed
  let openedAt = 0;
  let lastAt = 0;
  let count = 0;
  let bad = 0;
  let fresh = false;  // a new connection: the puppet drops the embedded take's weights at its first packet
  let latest = null;
  let pending = null;  // the newest packet, while the puppet is still loading
  let barsDirty = false;
  const arrivals = [];  // arrival times (ms) within the last second

  function show(state, badge, text) {
    box.dataset.state = state;
    const el = $("live-state");
    el.textContent = badge;
    el.className = "state state-" + state;
    const status = $("live-status");
    if (status.textContent !== text) status.textContent = text;
  }

  // The player's API once the frame's puppet is ready, else null.
  function puppetApi() {
    if (!frame) return null;
    try {
      const w = frame.contentWindow;
      if (w && w.puppet && w.document.documentElement.dataset.puppet === "ready") return w.puppet;
    } catch (err) {
      return null;  // the frame is between documents
    }
    return null;
  }

  function puppetFailed() {
    try {
      return frame.contentWindow.document.documentElement.dataset.puppet === "failed";
    } catch (err) {
      return false;
    }
  }

  function drive(msg) {
    const api = puppetApi();
    if (!api) {
      pending = msg;
      return;
    }
    if (fresh) {
      api.reset();
      fresh = false;
    }
    api.set(msg.weights || {}, msg.head, msg.eyes);
  }

  function readable(msg) {
    if (!msg || typeof msg !== "object" || Array.isArray(msg)) return false;
    const w = msg.weights;
    return w === undefined || (w !== null && typeof w === "object" && !Array.isArray(w));
  }

  function onMessage(e) {
    let msg = null;
    try { msg = JSON.parse(e.data); } catch (err) { msg = null; }
    if (!readable(msg)) {
      bad++;
      $("live-bad").textContent = String(bad);
      return;
    }
    const now = performance.now();
    count++;
    lastAt = now;
    arrivals.push(now);
    latest = msg;
    barsDirty = true;
    drive(msg);
    if (box.dataset.state !== "live") show("live", "live", `Live: packets arriving from ${url}.`);
  }

  function closeWords(e) {
    const words = {
      1000: "the bridge ended the feed",
      1001: "the bridge stopped (going away)",
      1006: "the connection dropped without a closing message: the bridge was stopped or the network went away",
      1009: "a message was too large",
      1011: "the bridge hit an error",
      1012: "the bridge is restarting",
    }[e.code] || "the connection ended";
    return `${words}${e.reason ? ` (“${e.reason}”)` : ""}, code ${e.code}`;
  }

  function connect() {
    attempts++;
    let s;
    try {
      s = new WebSocket(url);
    } catch (err) {
      show("error", "error", `Cannot open the feed ${url}: ${err.message}`);
      return;
    }
    socket = s;
    let opened = false;
    if (attempts === 1) show("connecting", "connecting", `Connecting to ${url}…`);
    s.onopen = () => {
      opened = true;
      everOpen = true;
      openedAt = performance.now();
      fresh = true;
      show("open", "connected", `Connected to ${url}; waiting for the first packet.`);
    };
    s.onmessage = onMessage;
    s.onclose = (e) => {
      if (socket !== s) return;
      socket = null;
      if (opened) {
        show("closed", "closed", `Closed: ${closeWords(e)}. Trying again every ${RETRY_MS / 1000} s.`);
      } else if (!everOpen) {
        show("waiting", "waiting", `Waiting for the bridge: nothing answers at ${url} yet (the connection was ` +
          "refused, or nothing listens there). Start it with the command below; this page connects by itself " +
          "once it is up.");
      }
      window.setTimeout(connect, RETRY_MS);
    };
  }

  function ago(ms) {
    const s = ms / 1000;
    return (s < 10 ? s.toFixed(2) : s.toFixed(0)) + " s ago";
  }

  function tick() {
    const now = performance.now();
    while (arrivals.length && now - arrivals[0] > 1000) arrivals.shift();
    $("live-rate").textContent = String(arrivals.length);
    $("live-count").textContent = String(count);
    $("live-age").textContent = lastAt ? ago(now - lastAt) : "none yet";
    if (socket && socket.readyState === WebSocket.OPEN) {
      const since = now - Math.max(lastAt, openedAt);
      if (since > QUIET_MS) {
        const n = Math.floor(since / 1000);
        const what = lastAt > openedAt ? `no packets for ${n} s` : `no packets yet in ${n} s`;
        show("quiet", "no packets", `Connected to ${url}, but ${what}: is the tracking app sending to the ` +
          "bridge's machine, on the UDP port below?");
      }
    }
    if (pending && puppetApi()) {
      const msg = pending;
      pending = null;
      drive(msg);
    }
    const note = $("live-puppet-error");
    if (frame && note) note.hidden = !puppetFailed();
  }

  function row() {
    const li = document.createElement("li");
    const name = document.createElement("span");
    name.className = "bar-name";
    const meter = document.createElement("meter");
    Object.assign(meter, { min: 0, max: 1, value: 0 });
    const out = document.createElement("output");
    li.append(name, meter, out);
    return li;
  }

  function drawBars() {
    const list = $("live-bars");
    const top = Object.entries(latest.weights || {})
      .map(([k, v]) => [k, Number(v)])
      .filter(([, v]) => Number.isFinite(v))
      .sort((a, b) => b[1] - a[1] || (a[0] < b[0] ? -1 : 1))
      .slice(0, BARS);
    while (list.children.length < top.length) list.append(row());
    while (list.children.length > top.length) list.lastElementChild.remove();
    top.forEach(([name, v], i) => {
      const li = list.children[i];
      li.dataset.name = name;
      li.children[0].textContent = name;
      li.children[1].value = Math.min(Math.max(v, 0), 1);
      li.children[2].textContent = v.toFixed(2);
    });
    $("live-bars-empty").hidden = top.length > 0;
    const head = latest.head;
    if (Array.isArray(head) && head.length >= 3) {
      $("live-head").textContent = head.slice(0, 3).map((a) => `${(Number(a) * DEG).toFixed(1)}°`).join(", ");
    }
  }

  function loop() {
    if (barsDirty && latest) {
      barsDirty = false;
      drawBars();
    }
    window.requestAnimationFrame(loop);
  }

  if (url) {
    connect();
    window.setInterval(tick, 250);
    window.requestAnimationFrame(loop);
  }
})();
