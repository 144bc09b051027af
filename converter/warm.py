"""Compile the numba kernels ahead of the first conversion: `facesvg warm` (run by `make setup`).

numba compiles a kernel on its first call and caches the machine code beside its module (or under
NUMBA_CACHE_DIR), keyed by the source file. A fresh install's first conversion would otherwise spend most of its
CPU compiling before it converts anything, each web worker's first job too (BENCHMARKS.md, start-up). Warming
converts the bundled sample's first frames in memory, once per job in WARM_JOBS (and verifies the first, as the web
worker verifies every job), and writes nothing but the cache; once the cache is warm it takes about as long as those
tiny conversions.
"""

from __future__ import annotations

import inspect
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from numba.core.registry import CPUDispatcher

from converter.bundled import sample_path
from converter.convert import convert_animation, load
from converter.options import ConversionOptions, Progress, no_progress
from converter.verify import verify_animation

WARM_FRAMES = 12  # enough for every kernel to run (6 left the player's colour keys out); few: quick once warm
WARM_JOBS = (  # the jobs whose kernels (or their argument types) differ; fap2d runs none of its own
    ConversionOptions(),
    ConversionOptions(shading="gouraud"),
    ConversionOptions(to="player"),  # its tracks are float64
    ConversionOptions(max_triangles=800),  # the triangle budget's (simplify.py)
    ConversionOptions(exact=True),  # each path's own colour steps (encode/steps.py)
)


@dataclass(frozen=True)
class Warmth:
    """What warm() did: kernels (name -> signatures) compiled now, and those loaded from the cache."""

    compiled: dict[str, int]
    loaded: dict[str, int]
    seconds: float
    cache: str  # the folder under which numba keeps the compiled code ('' if no kernel ran)

    def summary(self) -> str:
        """One line for the command."""
        if not self.compiled:
            return f"all {len(self.loaded)} kernels were already compiled ({self.seconds:.1f} s; cache: {self.cache})"
        return (f"compiled {len(self.compiled)} kernels in {self.seconds:.1f} s ({len(self.loaded)} were cached; "
                f"cache: {self.cache})")


def kernels() -> dict[str, CPUDispatcher]:
    """The numba kernels of every loaded converter module, by qualified name."""
    out = {}
    for name, module in list(sys.modules.items()):
        if module is None or not (name == "converter" or name.startswith("converter.")):
            continue
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == name:
                out[f"{name}.{attr}"] = value
    return out


def _counts(found: dict[str, CPUDispatcher], which: str) -> dict[str, int]:
    """Per kernel, how many signatures numba compiled ('cache_misses') or loaded ('cache_hits') in this process."""
    out = {}
    for name, kernel in found.items():
        n = sum(getattr(kernel.stats, which).values())
        if n:
            out[name] = n
    return out


def _modules() -> set[tuple[str, str]]:
    """(cache folder, file stem) of every module that defines kernels (folder '' where numba caches nothing)."""
    return {(k.stats.cache_path or "", Path(inspect.getfile(k.py_func)).stem) for k in kernels().values()}


def stale() -> bool:
    """Whether cached code may predate a kernel source: an index (.nbi) of the kernels' modules older than the
    newest of their sources. numba would load it without noticing a change to a callee in another file."""
    newest = max((os.path.getmtime(inspect.getfile(k.py_func)) for k in kernels().values()), default=0.0)
    return any(index.stat().st_mtime < newest
               for folder, stem in _modules() if folder for index in Path(folder).glob(f"{stem}.*.nbi"))


def forget() -> int:
    """Delete the cached machine code of the kernels' modules (every signature, and the stale entries of kernels
    that have since moved to other lines): the number of files removed. numba notices a change to a kernel's own
    file, not to a kernel it calls in another (idpass._frames compiles raster's draw_ids into itself), so after
    such a change the cache must go."""
    removed = 0
    for folder, stem in _modules():
        if not folder:
            continue
        for path in [*Path(folder).glob(f"{stem}.*.nbi"), *Path(folder).glob(f"{stem}.*.nbc")]:
            try:
                path.unlink()
                removed += 1
            except FileNotFoundError:  # another process removed it first
                pass
    return removed


def warm(progress: Progress = no_progress, fresh: bool = False) -> Warmth:
    """Run WARM_JOBS on the bundled sample's first WARM_FRAMES frames, so that numba compiles (or loads) and
    caches every kernel they call. With fresh, or when the cache is stale(), forget() it first, so that everything
    is compiled anew."""
    t = time.perf_counter()
    if fresh or stale():
        forget()
    anim = load(sample_path(), ConversionOptions()).sliced(0, WARM_FRAMES)
    for i, options in enumerate(WARM_JOBS):
        result = convert_animation(anim, options, lambda stage, f, i=i: progress(stage, (i + f) / len(WARM_JOBS)))
        if i == 0:  # the web worker verifies every job's output (the verifier's own kernels)
            verify_animation(result.data, anim)
    found = kernels()
    paths = [k.stats.cache_path for k in found.values() if k.stats.cache_path]
    cache = os.path.commonpath(paths) if paths else ""
    return Warmth(_counts(found, "cache_misses"), _counts(found, "cache_hits"), time.perf_counter() - t, cache)
