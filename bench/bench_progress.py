"""Progress and ETA (issue 16): what the CLI's bar and the web job page show during a long conversion.

Each case converts in a fresh interpreter (warm kernels) with a progress callback that records the wall time of
every call. From that record: the longest time the bar went without an update, and the ETA it showed (the CLI's
own `seconds_left` extrapolation, frozen between updates as the bar is) at a quarter, half and three quarters of
the run, as a ratio to the time really left (1.00 = right; below 1, too hopeful).

"Before" replays the same run as the code before 2026-12-06 reported it: the same calls up to the writer, its
2D stage mapped onto 0.1-0.6 instead of 0.1-WRITE_FROM, then 0.6 when the writer started and nothing until done
(the writers reported nothing). Those were exactly its calls, so both columns come from one run. For a triangle
budget (the mobile preset) "before" is the code of the day after (stop 41): the writer reported, the budget did not
(one jump to 0.1 when it was done, and the rest mapped onto 0.1-1); its replay keeps this run's budget times,
which are half what they were then. "Before" also extrapolates the ETA from the first call, as the CLI did; now it
counts from where loading ended (options.Eta), since no share set before reading the input can foresee its time.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

TITLE = "Progress and ETA during long conversions (issue 16)"
CASES = {  # label: (face, options)
    "capture-like face, flat SVG (7,993 x 335)": ("capture", {}),
    "capture-like face, Gouraud SVG": ("capture", {"shading": "gouraud"}),
    "capture-like face, WebGL player": ("capture", {"to": "player"}),
    "8k x 1,000 bench face, flat SVG": ("8k1000", {}),
    "ICT head driven by a 1,000-frame ARKit capture, flat SVG (50,996 x 1,000)": ("arkit1000", {}),
    "the same capture, mobile preset (bounded triangle budget)": ("arkit1000", {"preset": "mobile"}),
}
AT = (0.25, 0.5, 0.75)  # points of the run where the shown ETA is read
OLD_STAGE = (0.1, 0.6)  # where the 2D stage's progress went before (now 0.1 .. convert.WRITE_FROM)


def face(name: str):
    """The bench face a case converts."""
    if name == "capture":
        from bench.capture_like import capture_like
        return capture_like()
    from bench.bench_scale import face_file, load_face
    return load_face(face_file(1000, 8000, 0))


def child(name: str, options: dict) -> list[tuple[float, str, float]]:
    """In the measured interpreter: convert the face, return every progress call (seconds, stage, fraction)."""
    from converter.convert import convert_animation
    from converter.options import ConversionOptions

    calls: list[tuple[float, str, float]] = []

    def record(stage: str, fraction: float) -> None:
        calls.append((time.perf_counter(), stage, fraction))

    if name == "arkit1000":  # as `facesvg convert ICT --weights capture.csv` runs it: loading included
        from bench.bench_scale import ICT, write_capture
        from converter.convert import convert

        with tempfile.TemporaryDirectory() as tmp:
            write_capture(Path(tmp) / "capture.csv", 1000)
            convert(ICT, ConversionOptions.from_mapping({**options, "weights": str(Path(tmp) / "capture.csv")}),
                    progress=record)
        return calls
    convert_animation(face(name), ConversionOptions.from_mapping(options), progress=record)
    return calls


def before(calls: list[tuple[float, str, float]], write_from: float) -> list[tuple[float, str, float]]:
    """The calls the code before made in the same run (module docstring): before the writers reported progress,
    or, with a triangle budget, before the budget did."""
    from converter.convert import PREPARED_AT

    budget = [c for c in calls if c[1] == "simplify"]
    if budget:
        ready = budget[-1][2]
        done = budget[-1][0]
        return [(t, s, f if t < budget[0][0] else PREPARED_AT + (1 - PREPARED_AT) * (f - ready) / (1 - ready))
                for t, s, f in calls if s != "simplify" or t == done]
    out = []
    writing = False
    lo, hi = OLD_STAGE
    for t, s, f in calls:
        if s == "write":
            writing = True
            out.append((t, s, hi))
        elif s == "done":
            out.append((t, s, f))
        elif not writing:
            out.append((t, s, f if f < 0.1 else lo + (hi - lo) * (f - 0.1) / (write_from - 0.1)))
    return out


def shown(calls: list[tuple[float, str, float]], from_start: bool = False) -> tuple[float, list[float | None]]:
    """The longest gap between updates (s) and, at each point AT of the run, shown ETA / time really left: the
    CLI's options.Eta, or (from_start, as the CLI extrapolated before 2026-12-06's second change) from the first
    call."""
    from converter.options import Eta, seconds_left

    t0, end = calls[0][0], calls[-1][0]
    times = [t for t, _, _ in calls]
    gap = max((b - a for a, b in zip(times, times[1:])), default=0.0)
    eta = Eta()
    etas = [seconds_left(t - t0, f) if from_start else eta(s, f, t) for t, s, f in calls]
    ratios: list[float | None] = []
    for a in AT:
        now = t0 + a * (end - t0)
        left = etas[max(i for i, c in enumerate(calls) if c[0] <= now)]
        ratios.append(None if left is None else left / (end - now))
    return gap, ratios


def run() -> str:
    """Markdown: per case the run's wall time, its longest silence and the ETA ratios, now and before."""
    from converter.convert import WRITE_FROM

    def fmt(r: float | None) -> str:
        return "-" if r is None else f"{r:.2f}"

    rows = ["| case | run s | longest without an update s (before) | ETA shown / time left at "
            + ", ".join(f"{int(a * 100)} %" for a in AT) + " (before) |", "|---|---|---|---|"]
    for label, (name, options) in CASES.items():
        out = subprocess.run([sys.executable, __file__, "child", name, json.dumps(options)], cwd=ROOT,
                             capture_output=True, text=True, check=True)
        calls = [tuple(c) for c in json.loads(out.stdout.strip().splitlines()[-1])]
        gap, ratios = shown(calls)
        old_gap, old_ratios = shown(before(calls, WRITE_FROM), from_start=True)
        now = " / ".join(fmt(r) for r in ratios)
        then = " / ".join(fmt(r) for r in old_ratios)
        rows.append(f"| {label} | {calls[-1][0] - calls[0][0]:.1f} | {gap:.1f} ({old_gap:.1f}) | {now} ({then}) |")
        print(rows[-1], flush=True)
    return "\n".join([
        "One run per case (wall time matters here: it is what the bar extrapolates), from the conversion's first "
        "progress call to its last: the ICT head's from loading the head and the capture (`convert`, as the CLI "
        "runs it), the others' from a face already in memory (`convert_animation`: the bar starts at 0.1, which "
        "the loading has when there is a file; the ETA counts from the first call after loading). The writer now "
        "reports its phases "
        "(motion analysis, overlap search, the group decision's blocks of runs, the keys' blocks of paths, the "
        f"text), and the 2D stage ends at {WRITE_FROM} of the bar instead of 0.6: the flat SVG's writer takes 75-90 % "
        "of a long conversion. A triangle budget reports its passes over every frame, and takes a share of the bar "
        "sized to its work (`convert.prepared_at`). The web job page reads the same progress (and its cancel button "
        "acts at the next "
        "update, which inside the writer used to mean at the end). "
        + __doc__.split("\n\n")[2].replace("\n", " ").replace("WRITE_FROM", str(WRITE_FROM)),
        "",
        *rows,
    ])


if __name__ == "__main__":
    if len(sys.argv) > 3 and sys.argv[1] == "child":
        print(json.dumps(child(sys.argv[2], json.loads(sys.argv[3]))))
    else:
        print(run())
