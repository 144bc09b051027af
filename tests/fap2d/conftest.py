"""Fixtures for the fap2d package tests: a synthetic face with a stand-in deformation, packed with an Xface stream."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

XFACE = Path(__file__).resolve().parents[1] / "data" / "mpeg4" / "xface"


@pytest.fixture(scope="session")
def xface(small_data) -> Path:
    return small_data / "mpeg4" / "xface"


@pytest.fixture(scope="session")
def synthetic():
    """(anim, fdp, deform) of the synthetic face."""
    from standin import standin_deform, synthetic_face

    anim, fdp = synthetic_face()
    return anim, fdp, standin_deform(anim, fdp)


@pytest.fixture(scope="session")
def synthetic_package(synthetic, small_data):
    """(Package, zip bytes) of the synthetic face driven by Xface's joy.fap, 256 px."""
    from converter.mpeg4.fap import read_fap, write_fap
    from converter.options import ConversionOptions
    from converter.writers import fap2d

    anim, fdp, deform = synthetic
    stream = read_fap(small_data / "mpeg4" / "xface" / "joy.fap")
    pkg = fap2d.build_package(anim, fdp, stream, write_fap(stream), deform, ConversionOptions(to="fap2d", size=256))
    return pkg, fap2d.package_zip(pkg)


@pytest.fixture(scope="session")
def sample_face(sample_path):
    """The bundled sample face (undriven)."""
    from converter import formats

    return formats.load(sample_path)


@pytest.fixture(scope="session")
def joy_package(sample_face, small_data) -> bytes:
    """Zip of the sample face with Xface's joy.fap through fap2d.convert and the real MPEG-4 engine, 256 px."""
    from converter.options import ConversionOptions, Report
    from converter.writers import fap2d

    fdp = Path(__file__).resolve().parents[2] / "samples" / "face.fdp.json"
    options = ConversionOptions(to="fap2d", size=256, fap=str(small_data / "mpeg4/xface/joy.fap"), fdp=str(fdp))
    return fap2d.convert(sample_face, options, Report()).data
