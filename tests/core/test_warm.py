"""`facesvg warm`: every kernel a conversion (or the web job's verification) runs is compiled ahead, so that no
conversion compiles one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Kernels no conversion calls (library helpers the tests use): warm leaves them to their first call.
NOT_WARMED = {"converter.encode.overlap._apart_each", "converter.encode.overlap._has_each"}

ALL_KERNELS = """
import importlib, json, pkgutil, converter
from converter import warm
for m in pkgutil.walk_packages(converter.__path__, "converter."):
    importlib.import_module(m.name)
"""

JOBS = """
import json
from converter import warm
from converter.bundled import sample_path
from converter.convert import convert
from converter.options import ConversionOptions
from converter.formats import load
from converter.verify import verify_animation
for options in (ConversionOptions(), ConversionOptions(shading="gouraud", end=30), ConversionOptions(to="player"),
                ConversionOptions(frame=3), ConversionOptions(max_triangles=800, end=30)):
    convert(sample_path(), options)
verify_animation(convert(sample_path(), ConversionOptions(end=30)).data, load(sample_path()).sliced(0, 30))
found = warm.kernels()
print(json.dumps({"compiled": warm._counts(found, "cache_misses"), "loaded": warm._counts(found, "cache_hits")}))
"""


def _python(code: str, cache: Path) -> str:
    """Run code in a fresh interpreter whose numba cache is the folder cache: its stdout."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


@pytest.mark.slow
def test_after_warm_no_conversion_compiles_stale_code_is_seen_and_forget_empties_the_cache(tmp_path):
    cache = tmp_path / "numba"
    warmed = json.loads(_python("import json\nfrom converter import warm\nw = warm.warm()\n"
                                "print(json.dumps({'compiled': w.compiled, 'loaded': w.loaded}))", cache))
    assert warmed["compiled"] and not warmed["loaded"]  # an empty cache: everything compiled here
    every = json.loads(_python(ALL_KERNELS + "print(json.dumps({n: k.targetoptions.get('inline') == 'always' "
                                             "for n, k in warm.kernels().items()}))", cache))
    # inline="always" kernels are compiled into their callers; every other one is warmed or listed
    assert {n for n, inline in every.items() if not inline} - set(warmed["compiled"]) == NOT_WARMED

    again = subprocess.run([sys.executable, "-m", "converter.cli", "warm", "-q"], cwd=ROOT, capture_output=True,
                           text=True, env=dict(os.environ, NUMBA_CACHE_DIR=str(cache)), timeout=600)
    assert again.returncode == 0 and again.stdout.startswith("all ") and "already compiled" in again.stdout

    jobs = json.loads(_python(JOBS, cache).splitlines()[-1])
    assert jobs["compiled"] == {}  # flat, Gouraud, player, a still, a simplified mesh: nothing left to compile
    assert len(jobs["loaded"]) >= 20

    stale = "from converter import warm\nprint(warm.stale())"
    assert _python(stale, cache).strip() == "False"  # compiled after every kernel source was written
    index = next(cache.rglob("raster.draw_ids-*.nbi"))
    os.utime(index, (0, 0))  # as if compiled before raster.py last changed: numba itself would not notice
    assert _python(stale, cache).strip() == "True"

    kept = next(cache.rglob("*.nbi")).parent / "not-numba.txt"
    kept.write_text("a file of someone else's")
    removed = int(_python("from converter import convert, warm\nprint(warm.forget())", cache))
    assert removed >= len(warmed["compiled"])
    assert not list(cache.rglob("*.nbi")) and not list(cache.rglob("*.nbc"))
    assert kept.read_text() == "a file of someone else's"
