"""`make bench`: run every bench/bench_*.py section (or the ones named) and write BENCHMARKS.md.

Each section module has TITLE and run() -> markdown. Results are kept per section in bench/results/, so
running one section rewrites only its part; BENCHMARKS.md is assembled from all of them with the machine
and the date.
"""

from __future__ import annotations

import datetime
import importlib
import importlib.metadata
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def machine() -> str:
    """One line naming the CPU, cores, memory, Python and the GL renderer."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kb / 1048576:.0f} GiB RAM"
    except (OSError, ValueError, IndexError):
        pass
    return (f"{cpu}, {os.cpu_count()} cores{mem}, Linux {platform.release()}, Python {platform.python_version()} "
            f"({libraries()}), Mesa llvmpipe (EGL, software GL)")


def libraries() -> str:
    """The installed versions of the libraries the conversion's speed and memory depend on (unpinned: a fresh
    install takes the newest, so figures from two days may differ by them)."""
    found = []
    for name in ("numpy", "scipy", "numba", "llvmlite", "meshoptimizer"):
        try:
            found.append(f"{name} {importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            found.append(f"{name} -")
    return ", ".join(found)


def sections() -> list[str]:
    """Section module names in file order."""
    return sorted(p.stem for p in HERE.glob("bench_*.py"))


def main(argv: list[str]) -> int:
    names = argv or sections()
    unknown = [n for n in names if n not in sections()]
    if unknown:
        print(f"unknown section(s): {', '.join(unknown)}; have: {', '.join(sections())}", file=sys.stderr)
        return 2
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "out").mkdir(exist_ok=True)
    for name in names:
        mod = importlib.import_module(name)
        print(f"== {name}: {mod.TITLE}", flush=True)
        t = time.perf_counter()
        body = mod.run()
        stamp = datetime.date.today().isoformat()
        text = (f"## {mod.TITLE}\n\n_Measured {stamp} in {time.perf_counter() - t:.0f} s by `python bench/run.py {name}` "
                f"(Linux {platform.release()}; {libraries()})._\n\n{body.strip()}\n")
        (HERE / "results" / f"{name}.md").write_text(text)
        print(body, flush=True)
    assemble()
    return 0


def assemble() -> None:
    """BENCHMARKS.md = header + every stored section result."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        rev = "?"
    parts = [
        "# BENCHMARKS\n",
        f"Written by `make bench` on {datetime.date.today().isoformat()} (commit {rev or '?'}).\n",
        f"Machine: {machine()}. Each section names the kernel and libraries it was measured with.\n",
        "Times are medians of the repeats each section states; sizes and deviations are exact.\n",
    ]
    for name in sections():
        p = HERE / "results" / f"{name}.md"
        if p.exists():
            parts.append(p.read_text())
    (ROOT / "BENCHMARKS.md").write_text("\n".join(parts))


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    sys.exit(main(sys.argv[1:]))
