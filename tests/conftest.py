"""Shared fixtures: golden files, the shared and small data folders, the bundled sample, small synthetic animations."""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from converter import warm

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
SMALL_DATA = ROOT / "tests" / "data"  # small real files copied from SHARED_DATA by tests/data/derive.py
SAMPLE = ROOT / "samples" / "face.glb"


def pytest_configure(config):
    """Before any test (and any xdist worker): recompile the kernels if the cache may predate one of their sources.
    numba does not notice a change to a kernel's callee in another file, so the tests would run the old code;
    `make test` has done this already (make setup), a bare `pytest` after an edit has not."""
    if not hasattr(config, "workerinput") and warm.stale():
        print(f"facesvg: kernel sources changed since they were compiled: {warm.warm(fresh=True).summary()}")


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
    # A test that asks for the full data sets is a `shared` test and one that drives a browser a `browser` test,
    # whether or not it carries the marker, so `-m "not shared"` and `make test-fast` deselect them.
    for item in items:
        names = getattr(item, "fixturenames", ())
        if "shared_data" in names:
            item.add_marker(pytest.mark.shared)
        if "browser" in names and not item.get_closest_marker("browser"):
            item.add_marker(pytest.mark.browser)
        if {"firefox", "webkit"} & set(names):  # the other engines: `browser` tests too, and `engines`
            for marker in ("browser", "engines"):
                if not item.get_closest_marker(marker):
                    item.add_marker(getattr(pytest.mark, marker))
        # The web tests run on both queue backends; the RQ run (redis-server, a worker process, a forked work
        # horse per job) repeats the embedded run's checks and costs several times more, so it is `slow`.
        callspec = getattr(item, "callspec", None)
        if callspec is not None and callspec.params.get("app") == "rq":
            item.add_marker(pytest.mark.slow)


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
    with launched_chromium(exe) as b:
        yield b


@contextmanager
def launched_chromium(exe: str):
    """Chromium at exe, headless with this project's flags, for the length of the block (tests and bench)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


def require_engine(what: str, package: str) -> None:
    """Skip the calling test for a missing browser engine; fail instead when CI is set (.ci/run installs it)."""
    if os.environ.get("CI"):
        pytest.fail(f"{what} is not installed but CI is set: .ci/run must install it ({package})")
    pytest.skip(f"{what} not installed (apt-get install {package})")


@pytest.fixture(scope="session")
def firefox():
    """A headless Firefox ESR session over Marionette (tests/engines.py); skips locally without it, fails in CI."""
    from engines import firefox_path, launched_firefox

    exe = firefox_path()
    if not exe:
        require_engine("Firefox ESR", "firefox-esr")
    with launched_firefox(exe) as session:
        yield session


@pytest.fixture(scope="session")
def webkit():
    """A WebKitGTK MiniBrowser session under WebKitWebDriver and Xvfb (tests/engines.py); skips locally without
    them, fails in CI."""
    from engines import launched_webkit, webkit_paths

    paths = webkit_paths()
    if not paths:
        require_engine("WebKitGTK's WebKitWebDriver and MiniBrowser, or Xvfb,", "webkit2gtk-driver xvfb")
    with launched_webkit(*paths) as session:
        yield session


ARTIFACTS = ROOT / ".artifacts"


@pytest.fixture
def artifacts() -> Path:
    """Folder for screenshots and other test artifacts (ignored by git)."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


GOLDEN = ROOT / "tests" / "golden"


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
EXACT_ATTRIBUTES = {"id", "href", "{http://www.w3.org/1999/xlink}href", "class", "begin", "end"}


def _numbers_close(got: str, want: str) -> bool:
    """Same text with the numbers within one unit of want's last printed digit (or 1e-9 relative)."""
    if got == want:  # also spares hex colours such as #9e7561, which NUMBER reads as 9e7561
        return True
    if NUMBER.split(got) != NUMBER.split(want):
        return False
    got_n, want_n = NUMBER.findall(got), NUMBER.findall(want)
    if len(got_n) != len(want_n):
        return False
    for g, w in zip(got_n, want_n):
        mantissa = re.split("[eE]", w)[0]
        exponent = int(re.split("[eE]", w)[1]) if re.search("[eE]", w) else 0
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        try:
            unit = 10.0 ** (exponent - decimals)
            if abs(float(g) - float(w)) > max(1.0001 * unit, 1e-9 * abs(float(w))):
                return False
        except OverflowError:  # a hex colour read as a huge exponent: it is not a number to round
            return False
    return True


def golden_mismatch(got, want, path: str = "") -> str | None:
    """Where two XML trees differ beyond last-digit noise (None when they match): tags, attributes, text."""
    here = f"{path}/{etree.QName(want).localname}"
    if got.tag != want.tag or set(got.attrib) != set(want.attrib) or len(got) != len(want):
        return f"{here}: element, attribute names or child count differ"
    for key, value in want.attrib.items():
        same = got.attrib[key] == value if key in EXACT_ATTRIBUTES else _numbers_close(got.attrib[key], value)
        if not same:
            return f"{here}/@{key}: {got.attrib[key][:80]!r} != {value[:80]!r}"
    for a, b in ((got.text, want.text), (got.tail, want.tail)):
        if not _numbers_close((a or "").strip(), (b or "").strip()):
            return f"{here}: text {(a or '')[:80]!r} != {(b or '')[:80]!r}"
    for g, w in zip(got, want):
        where = golden_mismatch(g, w, here)
        if where:
            return where
    return None


@pytest.fixture
def golden(update_golden):
    """golden(name, svg_bytes): compare with tests/golden/name (canonical XML); --update-golden rewrites.

    Structure, names and every character but numbers must match; a number may differ by one unit of its last
    printed digit, so a last-bit change in numpy or scipy does not fail a golden, while any change we make does.
    """

    def check(name: str, data: bytes) -> None:
        canon = etree.tostring(etree.fromstring(data), method="c14n")
        path = GOLDEN / name
        if update_golden:
            GOLDEN.mkdir(exist_ok=True)
            path.write_bytes(canon)
            return
        if not path.exists():
            pytest.fail(f"golden file {path.name} missing: run `pytest --update-golden` and review it")
        where = golden_mismatch(etree.fromstring(canon), etree.fromstring(path.read_bytes()))
        assert where is None, f"{name} differs from its golden file at {where} (review, then `pytest --update-golden`)"

    return check
