"""Start-up (issue 16): what a small job costs a fresh install, and after `facesvg warm`.

Each figure is a fresh interpreter's whole life (imports included), as a user's `facesvg` command pays it: CPU
user+sys of the process and its threads, its peak RSS, and the wall time the parent waited. Every run gets its own
numba cache folder (NUMBA_CACHE_DIR): empty for the cold rows, filled by one `facesvg warm` for the others, so the
figures neither use nor disturb the checkout's own cache.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench import usage

TITLE = "Start-up: a fresh install's first conversion, and small jobs after `facesvg warm` (issue 16)"
REPEATS = 3
TINY = ["convert", "--sample", "--end", "10", "-q"]  # the bundled sample's first 10 frames
SMALL = ["convert", "--sample", "-q"]  # all 121 frames of it
JOBS = {  # row label: (facesvg arguments or None for the import alone, whether the cache starts warm)
    "import the command (`import converter.cli`)": (None, True),
    "first conversion after install, no `warm` (sample, 10 frames)": (TINY, False),
    "`facesvg warm` on an empty cache (what `make setup` adds)": (["warm", "-q"], False),
    "`facesvg warm` again (already compiled)": (["warm", "-q"], True),
    "conversion after `warm` (sample, 10 frames)": (TINY, True),
    "conversion after `warm` (sample, all 121 frames)": (SMALL, True),
}


def child(args: list[str]) -> dict:
    """In the measured interpreter: run `facesvg args` (or only import it), report CPU and peak RSS."""
    from converter import cli  # the import is part of what is measured

    if args:
        with tempfile.TemporaryDirectory() as tmp:
            os.chdir(tmp)  # convert --sample writes face.svg here
            if cli.main(args):
                raise SystemExit(f"facesvg {' '.join(args)} failed")
    return {"cpu": usage.cpu(), "peak_mb": usage.peak_mb()}


def measure(args: list[str] | None, warm: bool, cache: Path) -> dict:
    """One run in a fresh interpreter with its own numba cache: a copy of the warm one, or empty."""
    shutil.rmtree(cache, ignore_errors=True)
    if warm:
        shutil.copytree(cache.with_name("warm"), cache)
    else:
        cache.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    t = time.perf_counter()
    out = subprocess.run([sys.executable, __file__, "child", json.dumps(args or [])], env=env, cwd=ROOT,
                         capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    r["wall"] = time.perf_counter() - t
    return r


def run() -> str:
    """Markdown: each job's median CPU, wall and peak over REPEATS runs."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        subprocess.run([sys.executable, "-m", "converter.cli", "warm", "-q"], cwd=ROOT, check=True,
                       env=dict(os.environ, NUMBA_CACHE_DIR=str(folder / "warm")), capture_output=True)
        rows = ["| job | CPU s | wall s | peak MB |", "|---|---|---|---|"]
        for label, (args, warm) in JOBS.items():
            runs = [measure(args, warm, folder / "run") for _ in range(REPEATS)]
            med = {k: statistics.median(r[k] for r in runs) for k in ("cpu", "wall", "peak_mb")}
            rows.append(f"| {label} | {med['cpu']:.2f} | {med['wall']:.2f} | {med['peak_mb']:.0f} |")
            print(rows[-1], flush=True)
    return "\n".join([
        f"Medians of {REPEATS} runs, each a fresh interpreter (imports included) with its own numba cache folder: "
        "empty for a fresh install, else a copy of one that `facesvg warm` filled. `make setup` runs `facesvg warm` "
        "(and again, `--fresh`, whenever a kernel's source changes), so `make run`'s conversion and every later "
        "one start warm; a `pip install` user runs it once (README). CPU is user+sys of the process and its "
        "threads (and any child it waits for); peak is its high-water RSS (VmHWM, `bench/usage.py`; ru_maxrss would start at the bench parent's size).",
        "",
        *rows,
        "",
        "What is left of a warm small job is mostly the imports (numpy, numba, scipy and the converter: the first "
        "row), then loading the cached kernels. The issue measured ~3 s CPU for the import and first conversion of a "
        "tiny file and set no figure for \"feel instant\". The cold row is also what a kernel's first call costs in "
        "a process whose cache misses its argument types: tests/core/test_warm.py checks that flat, Gouraud, player, "
        "still and simplified conversions find every kernel warm.",
    ])


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "child":
        print(json.dumps(child(json.loads(sys.argv[2]))))
    else:
        print(run())
