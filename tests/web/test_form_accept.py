"""The upload form's file inputs offer every file kind the loaders read (the accept lists browsers filter by)."""

from __future__ import annotations

import pytest
from lxml import html as lxml_html

from converter import formats
from converter.formats import captures
from web.conftest import glb_bytes, make_app

# One file of each kind converter.formats reads as a face, as its first bytes.
FACES = {
    "glb": glb_bytes(),
    "gltf": b'{"asset": {"version": "2.0"}}',
    "zip": b"PK\x03\x04\x14\x00\x00\x00\x00\x00" + b"\0" * 16 + b"\x08\x00\x00\x00f001.obj",
    "obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "ply": b"ply\nformat ascii 1.0\nelement vertex 3\n",
}


@pytest.fixture(scope="module")
def form(tmp_path_factory):
    app = make_app(tmp_path_factory.mktemp("accept"), "embedded")
    try:
        page = lxml_html.fromstring(app.test_client().get("/").get_data(as_text=True))
    finally:
        app.extensions["facesvg_queue"].close()
    inputs = [el for el in page.iter("input") if el.get("type") == "file"]
    return {el.get("name"): (el.get("accept") or "").split(",") for el in inputs}


def test_the_face_input_takes_every_kind_the_loader_reads(form):
    for kind, head in FACES.items():
        assert formats.sniff(head) == kind
        assert f".{kind}" in form["file"], (kind, form["file"])
    assert ".vrm" in form["file"]  # a VRM avatar is a GLB
    assert ".ply" in form["clone_target"] and ".vrm" in form["clone_target"]  # a clone target is a face too


def test_the_capture_input_lists_the_capture_registry(form):
    offered = captures.extensions()
    assert offered and form["weights"] == list(offered)
    assert {".csv", ".json"} <= set(form["weights"])


def test_the_point_cache_input_takes_every_cache(form):
    assert {".pc2", ".mdd", ".npy"} <= set(form["cache"])
