"""Fixtures for the fap2d package tests: a synthetic face with a stand-in deformation, packed with an Xface stream."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from converter import formats
from converter.convert import convert_animation
from converter.mpeg4 import fat2d
from converter.mpeg4.fap import read_fap
from converter.options import ConversionOptions
from converter.writers import fap2d

sys.path.insert(0, str(Path(__file__).resolve().parent))  # player.py, standin.py, reference_render.py

from standin import standin_deform, synthetic_face

XFACE = Path(__file__).resolve().parents[1] / "data" / "mpeg4" / "xface"


@pytest.fixture(scope="session")
def xface(small_data) -> Path:
    return small_data / "mpeg4" / "xface"


@pytest.fixture(scope="session")
def synthetic():
    """(anim, fdp, deform) of the synthetic face."""
    anim, fdp = synthetic_face()
    return anim, fdp, standin_deform(anim, fdp)


@pytest.fixture(scope="session")
def synthetic_package(synthetic, small_data):
    """(Package, zip bytes) of the synthetic face driven by Xface's joy.fap, 256 px."""
    anim, fdp, deform = synthetic
    stream = read_fap(small_data / "mpeg4" / "xface" / "joy.fap")
    pkg = fap2d.package(fat2d.build(anim, fdp, stream, deform, ConversionOptions(to="fap2d", size=256)))
    return pkg, fap2d.package_zip(pkg)


@pytest.fixture(scope="session")
def sample_face(sample_path):
    """The bundled sample face (undriven)."""
    return formats.load(sample_path)


@pytest.fixture(scope="session")
def joy_package(sample_face, small_data) -> bytes:
    """Zip of the sample face with Xface's joy.fap through convert_animation and the real MPEG-4 engine, 256 px."""
    fdp = Path(__file__).resolve().parents[2] / "samples" / "face.fdp.json"
    options = ConversionOptions(to="fap2d", size=256, fap=str(small_data / "mpeg4/xface/joy.fap"), fdp=str(fdp))
    return convert_animation(sample_face, options).data
