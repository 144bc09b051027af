"""Fixtures of the puppet tests: the generated face (tests/puppet/faces.py) as a file, a MorphFace and a Puppet."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from converter.formats.morphs import load_morph_face
from converter.options import ConversionOptions
from converter.puppet import puppet_of
from faces import face_zip


@pytest.fixture(scope="session")
def face_path(tmp_path_factory) -> Path:
    """The generated face as an OBJ shape zip on disk."""
    path = tmp_path_factory.mktemp("puppet") / "generated.zip"
    path.write_bytes(face_zip())
    return path


@pytest.fixture(scope="session")
def face(face_path):
    """The generated face as a MorphFace."""
    return load_morph_face(face_path)


@pytest.fixture(scope="session")
def puppet(face):
    """The generated face's puppet with the default options (512 px, perspective, flat)."""
    return puppet_of(face, ConversionOptions())
