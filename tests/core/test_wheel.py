"""A wheel that works: built from a copy of the tree, installed into a fresh venv, it converts and serves the UI."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import sysconfig
import time
import urllib.request
from pathlib import Path

import pytest
from lxml import etree

from conftest import ROOT, SAMPLE
from converter import formats

SOURCES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "converter", "webapp", "templates", "static",
           "samples")

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """bin/ of a fresh venv holding only the wheel; dependencies come from this environment's site-packages."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            src.mkdir(exist_ok=True)
            shutil.copy(path, src / name)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    # No build isolation, so no network: the build uses this environment's setuptools (a test extra).
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(tmp / "dist")], check=True, env=env, cwd=tmp)
    (wheel,) = (tmp / "dist").glob("facesvg-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    purelib = "import sysconfig; print(sysconfig.get_path('purelib'))"
    site = Path(subprocess.run([venv / "bin" / "python", "-c", purelib], check=True, capture_output=True,
                               text=True).stdout.strip())
    # A path line in a .pth adds this environment's packages but runs none of its .pth files, so a development
    # install of facesvg there stays invisible; the venv's own site-packages (the wheel) comes first.
    deps = dict.fromkeys([sysconfig.get_path("purelib"), sysconfig.get_path("platlib")])
    (site / "facesvg-test-deps.pth").write_text("".join(f"{p}\n" for p in deps))
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-deps",
                    "-q", str(wheel)], check=True, env=env, cwd=tmp)
    where = subprocess.run([venv / "bin" / "python", "-c", "import converter, webapp; print(converter.__file__)"],
                           check=True, capture_output=True, text=True, env=env, cwd=tmp).stdout.strip()
    assert Path(where).is_relative_to(site), f"the venv imports facesvg from {where}, not from the wheel"
    return venv / "bin"


def test_installed_wheel_converts_the_bundled_sample(installed, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out, report = tmp_path / "out.svg", tmp_path / "report.json"
    r = subprocess.run([installed / "facesvg", "convert", "--sample", "-o", out, "--size", "128", "--end", "10", "-q",
                        "--report", report], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    root = etree.fromstring(out.read_bytes())
    assert root.tag == "{http://www.w3.org/2000/svg}svg" and root.findall(".//{http://www.w3.org/2000/svg}animate")
    counts = json.loads(report.read_text())["counts"]
    sample = formats.load(SAMPLE)
    assert counts["frames"] == 10 and counts["vertices"] == sample.n_vertices


def test_installed_wheel_serves_the_ui_and_its_static_files(installed, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    port = _free_port()
    proc = subprocess.Popen([installed / "facesvg", "serve", "--host", "127.0.0.1", "--port", str(port),
                             "--workers", "1", "--instance", tmp_path / "instance"],
                            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        page = None
        for _ in range(600):  # the first start imports numba, scipy and trimesh
            if proc.poll() is not None:
                pytest.fail(f"facesvg serve exited: {proc.stdout.read()}")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as resp:
                    page = resp.read().decode()
                break
            except OSError:
                time.sleep(0.1)
        assert page is not None, "facesvg serve did not answer"
        assert page.lstrip().lower().startswith("<!doctype html") and "<form" in page and 'name="file"' in page
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/static/style.css", timeout=5) as resp:
            css = resp.read()
            assert resp.headers.get_content_type() == "text/css"
        assert css == (ROOT / "static" / "style.css").read_bytes()
    finally:
        proc.terminate()
        proc.wait(30)


def test_installed_wheel_writes_the_player(installed, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = tmp_path / "face.html"
    r = subprocess.run([installed / "facesvg", "convert", "--sample", "--to", "player", "-o", out, "--size", "64",
                        "--end", "4", "-q"], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    text = out.read_text(encoding="utf-8")
    assert "window.facesvgPlayer" in text  # the package data script, inlined
