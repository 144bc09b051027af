"""A Live Link Face packet sent on loopback to `facesvg live`, drawn by the puppet player in headless Chromium:
the latency from the UDP send to the puppet's drawn frame changing (target: within 2 display frames)."""

from __future__ import annotations

import json
import statistics
import time

import numpy as np
import pytest
from puppet.faces import face_zip

from converter.formats.morphs import load_morph_face
from converter.options import ConversionOptions, Report
from converter.puppet import puppet_of
from converter.writers import puppet as writer

from .build import live_command, llf_curves, llf_packet, read_lines, send

ROUNDS = 40
FRAMES = 2  # the target, in display frames

INSTRUMENT = """(url) => {
  // Each draw of the puppet (its frame counter moving, seen by a later rAF callback of the same frame): the
  // wall-clock time and a checksum of the drawn positions; each live message's arrival; the first rAF intervals.
  const live = window.__live = {draws: [], arrivals: [], rafs: []};
  let seen = puppet.frames;
  const poll = (t) => {
    if (live.rafs.length < 121) live.rafs.push(t);
    if (puppet.frames !== seen) {
      seen = puppet.frames;
      const at = performance.timeOrigin + performance.now(), xy = puppet.positions().xy;
      let sum = 0;
      for (let i = 0; i < xy.length; i++) sum += xy[i] * ((i % 7) + 1);
      live.draws.push([at, sum, puppet.weights().jawOpen]);
    }
    requestAnimationFrame(poll);
  };
  requestAnimationFrame(poll);
  const socket = puppet.connect(url);
  socket.addEventListener("message", () => live.arrivals.push(performance.timeOrigin + performance.now()));
  return new Promise((ok, fail) => {
    socket.addEventListener("open", () => ok(true));
    socket.addEventListener("error", () => fail(new Error("no connection to " + url)));
  });
}"""


def clock_offset(page) -> tuple[float, float]:
    """The page's wall clock (timeOrigin + now, ms) minus Python's time.time() (ms), from the quickest of 15 round
    trips, and that round trip's half (the offset's uncertainty)."""
    best = (float("inf"), 0.0)
    for _ in range(15):
        t0 = time.time() * 1000
        js = page.evaluate("() => performance.timeOrigin + performance.now()")
        t1 = time.time() * 1000
        if t1 - t0 < best[0]:
            best = (t1 - t0, js - (t0 + t1) / 2)
    return best[1], best[0] / 2


@pytest.mark.browser
def test_a_udp_packet_is_drawn_within_two_frames(browser, tmp_path, artifacts):
    face_path = tmp_path / "face.zip"
    face_path.write_bytes(face_zip())
    puppet = puppet_of(load_morph_face(face_path), ConversionOptions(size=256))
    html = tmp_path / "puppet.html"
    html.write_bytes(writer.write(puppet, ConversionOptions(), Report()))
    proc = live_command("--llf-port", "0", "--ifm-port", "0", "--vmc-port", "0", "--ws-port", "0")
    page = None
    try:
        listening, point = read_lines(proc, 2)
        llf = int(listening.split("Live Link Face on UDP ")[1].split(",")[0])
        url = point.split("live=")[1].split(",")[0]
        page = browser.new_page(viewport={"width": 512, "height": 512})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(html.as_uri() + "?paused")
        page.wait_for_function("() => document.documentElement.dataset.puppet", timeout=60000)
        assert page.evaluate("() => document.documentElement.dataset.puppet") == "ready", errors
        page.evaluate(INSTRUMENT, url)
        offset, uncertainty = clock_offset(page)
        rng = np.random.default_rng(11)
        sends, jaws = [], []
        for k in range(ROUNDS):
            drawn = page.evaluate("() => window.__live.draws.length")
            time.sleep(float(rng.uniform(0.02, 0.04)))  # a random phase against the display's frames
            jaw = 0.1 + 0.8 * (k % 2)
            sends.append(time.time() * 1000 + offset)
            send(llf, llf_packet(llf_curves(jaw, yaw=0.05 * (k % 3))))
            jaws.append(jaw)
            page.wait_for_function("(n) => window.__live.draws.length > n", arg=drawn, timeout=10000)
        live = page.evaluate("() => window.__live")
        offset_after, _ = clock_offset(page)
    finally:
        if page is not None:
            page.close()
        proc.terminate()
        proc.communicate(timeout=30)
    draws, arrivals = live["draws"], live["arrivals"]
    assert len(draws) == ROUNDS and len(arrivals) == ROUNDS, (len(draws), len(arrivals))  # one draw per packet
    assert [round(d[2], 4) for d in draws] == pytest.approx(jaws, abs=1e-4)  # each draw shows its own packet
    sums = [d[1] for d in draws]
    assert all(abs(a - b) > 1e-3 for a, b in zip(sums, sums[1:]))  # and each changed the drawn face
    frame_ms = float(np.median(np.diff(live["rafs"])))
    latency = [d[0] - s for d, s in zip(draws, sends)]
    to_page = [a - s for a, s in zip(arrivals, sends)]
    figures = {
        "rounds": ROUNDS, "frame_ms": round(frame_ms, 2),
        "median_ms": round(statistics.median(latency), 2), "max_ms": round(max(latency), 2),
        "p90_ms": round(float(np.percentile(latency, 90)), 2), "min_ms": round(min(latency), 2),
        "udp_to_message_median_ms": round(statistics.median(to_page), 2),
        "udp_to_message_max_ms": round(max(to_page), 2),
        "clock_uncertainty_ms": round(uncertainty, 3), "clock_drift_ms": round(offset_after - offset, 3),
    }
    (artifacts / "live_latency.json").write_text(json.dumps(figures, indent=2))
    print("facesvg live latency:", figures)
    assert min(latency) > -1.0 - uncertainty  # the clocks agree: nothing is drawn before it is sent
    assert statistics.median(latency) <= FRAMES * frame_ms, figures
