"""Where a conversion's memory peaks: a sampler thread records the traced peak (tracemalloc, which numpy
reports to) and the converter frames of the main thread every 50 ms; prints the places with the highest peaks.

    python bench/memory_peak.py                  # the capture-like face (335 frames), default options
    python bench/memory_peak.py --frames 1000    # a longer capture-like face
    python bench/memory_peak.py face.glb --to player

Only the conversion is traced (the face's generation is not). Tracing slows it down ~2x.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
import traceback
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from converter import formats
from converter.convert import convert_animation
from converter.options import ConversionOptions


def sample_peaks(work, interval: float = 0.05, depth: int = 4) -> dict[str, int]:
    """Run work() while sampling; per place (the innermost converter frames) the largest traced bytes seen."""
    main = threading.get_ident()
    peaks: dict[str, int] = {}
    done = threading.Event()

    def sampler() -> None:
        while not done.is_set():
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            frame = sys._current_frames().get(main)
            stack = [f for f in traceback.extract_stack(frame) if "converter" in f.filename][-depth:]
            where = " <- ".join(f"{f.name}:{f.lineno}" for f in reversed(stack)) or "(outside the converter)"
            peaks[where] = max(peaks.get(where, 0), peak)
            time.sleep(interval)

    tracemalloc.start()
    thread = threading.Thread(target=sampler, daemon=True)
    thread.start()
    try:
        work()
    finally:
        done.set()
        thread.join()
        tracemalloc.stop()
    return peaks


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", nargs="?", help="a face file (default: the capture-like benchmark face)")
    ap.add_argument("--frames", type=int, default=None, help="capture-like face: number of frames")
    ap.add_argument("--to", default="svg")
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args(argv)
    if args.input:
        anim = formats.load(args.input)
    else:
        from bench.capture_like import FRAMES, capture_like
        anim = capture_like(n_frames=args.frames or FRAMES)
    options = ConversionOptions(to=args.to)
    peaks = sample_peaks(lambda: convert_animation(anim, options))
    for where, peak in sorted(peaks.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"{peak / 1e6:9.1f} MB  {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
