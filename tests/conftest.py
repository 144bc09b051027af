"""Shared fixtures: golden files, the shared and small data folders, the bundled sample, small synthetic animations."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
SMALL_DATA = ROOT / "tests" / "data"  # small real files copied from SHARED_DATA by tests/data/derive.py
SAMPLE = ROOT / "samples" / "face.glb"


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", help="rewrite golden files instead of comparing")


@pytest.fixture
def update_golden(request) -> bool:
    return bool(request.config.getoption("--update-golden"))


def require_shared_data() -> Path:
    """SHARED_DATA; skips the calling test where it is missing, fails instead when CI is set (CI has the data)."""
    if SHARED_DATA.is_dir():
        return SHARED_DATA
    if os.environ.get("CI"):
        pytest.fail(f"the full data sets are missing but CI is set: CI must check out ../shared beside the repo "
                    f"({SHARED_DATA})")
    pytest.skip(f"needs the full data sets in {SHARED_DATA} (not in this clone)")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data, the full data sets (the ICT FaceKit head): skips without it, fails under CI."""
    return require_shared_data()


@pytest.fixture(scope="session")
def small_data() -> Path:
    """tests/data: the small real files (Xface FAP/FDP, MediaPipe OBJ), same layout as ../shared/data."""
    return SMALL_DATA


def pytest_collection_modifyitems(config, items):
    # A test that asks for the full data sets is a `shared` test, so `-m "not shared"` deselects it.
    for item in items:
        if "shared_data" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.shared)


def pytest_runtest_setup(item):
    if item.get_closest_marker("shared"):
        require_shared_data()


@pytest.fixture(scope="session")
def sample_path() -> Path:
    return SAMPLE


def cube_animation(n_frames: int = 4, fps: float = 10.0):
    """A unit cube spinning about y, outward counter-clockwise faces: a small exact test subject."""
    from converter.animation import FaceAnimation, Part

    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    faces = np.array(faces, np.int32)
    # Make every face wind counter-clockwise seen from outside.
    cent = v[faces].mean(1)
    n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    flip = (n * cent).sum(1) < 0
    faces[flip] = faces[flip][:, ::-1]
    frames = []
    for k in range(n_frames):
        a = np.radians(20 * k)
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], np.float32)
        frames.append(v @ r.T)
    skin = (Part("skin", (0.8, 0.6, 0.5)),)
    return FaceAnimation(np.stack(frames), faces, np.zeros(len(faces), np.int32), skin, fps, "cube")


@pytest.fixture
def cube():
    return cube_animation()


CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]


def chromium_path() -> str | None:
    """Debian's Chromium, if installed."""
    import shutil

    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="session")
def browser():
    """A headless Chromium driven by Playwright; skips locally without Chromium, fails when CI is set."""
    exe = chromium_path()
    if not exe:
        if os.environ.get("CI"):
            pytest.fail("Chromium is not installed but CI is set: .ci/run must install it")
        pytest.skip("Chromium not installed (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


ARTIFACTS = ROOT / ".artifacts"


@pytest.fixture
def artifacts() -> Path:
    """Folder for screenshots and other test artifacts (ignored by git)."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


GOLDEN = ROOT / "tests" / "golden"


@pytest.fixture
def golden(update_golden):
    """golden(name, svg_bytes): compare canonical XML (lxml c14n) with tests/golden/name; --update-golden rewrites."""
    from lxml import etree

    def check(name: str, data: bytes) -> None:
        canon = etree.tostring(etree.fromstring(data), method="c14n")
        path = GOLDEN / name
        if update_golden:
            GOLDEN.mkdir(exist_ok=True)
            path.write_bytes(canon)
            return
        if not path.exists():
            pytest.fail(f"golden file {path.name} missing: run `pytest --update-golden` and review it")
        expected = etree.tostring(etree.fromstring(path.read_bytes()), method="c14n")
        assert canon == expected, f"{name} differs from its golden file (review, then `pytest --update-golden`)"

    return check
