"""glTF colours are linear (baseColorFactor, COLOR_0) or sRGB (textures); the SVG shows what a glTF viewer shows.

Expected values come from the glTF 2.0 spec and the sRGB formula, with our light rig as the three.js reference
player sets it up (tests/reference/player.js: ambient 0.30, key light 0.75 towards (-0.35, 0.45, 0.82) in eye
space, Lambert in linear light, sRGB output), not from our own code.
"""

from __future__ import annotations

import io
import json
import re
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from converter.cli import main
from converter.cloning.dense import skin_faces
from converter.convert import convert_animation
from converter.export.gltf_builder import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from converter.formats.gltf import load_gltf
from converter.options import ConversionOptions
from tests.formats.helpers import TRI, linear, srgb, triangle_scene
from tests.formats.test_gltf_textures import png, textured_triangle

HERE = Path(".")
KEY = np.array([-0.35, 0.45, 0.82])
# The triangle faces the default front camera: its normal is the eye-space +z axis.
FACING_LIGHT = 0.30 + 0.75 * max(0.0, KEY[2] / np.linalg.norm(KEY))


def flat_fills(glb: bytes) -> list[np.ndarray]:
    """The 8-bit fill colours of a flat still of the glTF, one per colour class."""
    svg = convert_animation(load_gltf(glb, HERE, None, "colour"), ConversionOptions(frame=0)).data.decode()
    return [np.array([int(h[i:i + 2], 16) for i in (0, 2, 4)]) for h in re.findall(r"\{color:#([0-9a-f]{6})\}", svg)]


def expected_8bit(linear_rgb) -> np.ndarray:
    """What three.js shows for a linear base colour lit by our rig, 0..255."""
    return np.round(srgb(np.asarray(linear_rgb, np.float64) * FACING_LIGHT) * 255)


def test_base_colour_factor_half_renders_as_three_js_shows_it():
    b, _ = triangle_scene(material={"name": "Grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}})
    (fill,) = flat_fills(b.glb())
    want = expected_8bit([0.5, 0.5, 0.5])
    assert 175 <= want[0] <= 185  # ~#b3b3b3 as the three.js reference draws it, not ~#757575
    assert np.abs(fill - want).max() <= 1, (fill, want)


def test_vertex_colours_are_linear_too():
    b = GltfBuilder()
    c = b.accessor(np.float32([[0.5, 0.2, 0.1]] * 3), target=ARRAY_BUFFER)
    triangle_scene(b, extra_prim={"attributes": {"POSITION": b.accessor(TRI, target=ARRAY_BUFFER), "COLOR_0": c}},
                   material={"name": "Skin", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 1, 1, 1]}})
    (fill,) = flat_fills(b.glb())
    assert np.abs(fill - expected_8bit([0.4, 0.2, 0.1])).max() <= 1, fill


def test_texture_of_a_known_srgb_colour_renders_decoded_and_lit():
    b = textured_triangle()
    b.doc["images"][0] = {"bufferView": b.view(png(np.full((2, 2, 3), [200, 100, 50], np.uint8))),
                          "mimeType": "image/png"}
    (fill,) = flat_fills(b.glb())
    assert np.abs(fill - expected_8bit(linear(np.array([200, 100, 50]) / 255))).max() <= 1, fill


def two_primitive_mesh() -> bytes:
    """One node 'Wolf3D_Head' whose mesh has two primitives: mat_skin and Wolf3D_Eye, each its own factor."""
    b = GltfBuilder()
    pos = b.accessor(np.concatenate([TRI, TRI + [0, 0, 0.1]]).astype(np.float32), minmax=True, target=ARRAY_BUFFER)
    prims = []
    for k, (name, factor) in enumerate((("mat_skin", [0.6, 0.3, 0.2, 1]), ("Wolf3D_Eye", [0.9, 0.9, 0.9, 1]))):
        idx = b.accessor(np.arange(3 * k, 3 * k + 3, dtype=np.uint16), target=ELEMENT_ARRAY_BUFFER)
        mat = b.add("materials", {"name": name, "pbrMetallicRoughness": {"baseColorFactor": factor}})
        prims.append({"attributes": {"POSITION": pos}, "indices": idx, "material": mat})
    mesh = b.add("meshes", {"name": "Head", "primitives": prims})
    b.add("scenes", {"nodes": [b.add("nodes", {"name": "Wolf3D_Head", "mesh": mesh})]})
    return b.glb()


def test_one_part_per_primitive_with_its_label_semantic_name_and_colour():
    a = load_gltf(two_primitive_mesh(), HERE, None, "avatar")
    assert [(p.name, p.label) for p in a.parts] == [("skin", "Wolf3D_Head/mat_skin"), ("eye", "Wolf3D_Head/Wolf3D_Eye")]
    np.testing.assert_allclose([p.color for p in a.parts], srgb([[0.6, 0.3, 0.2], [0.9, 0.9, 0.9]]), atol=1e-6)
    assert a.part_ids.tolist() == [0, 1]


@pytest.mark.parametrize("as_json", [True, False])
def test_info_lists_parts_with_labels_and_colours(tmp_path, as_json):
    path = tmp_path / "avatar.glb"
    path.write_bytes(two_primitive_mesh())
    out = io.StringIO()
    with redirect_stdout(out):
        assert main(["info", str(path)] + (["--json"] if as_json else [])) == 0
    skin = "#" + "".join(f"{int(round(c * 255)):02x}" for c in srgb([0.6, 0.3, 0.2]))
    if as_json:
        info = json.loads(out.getvalue())
        assert info["parts"] == {"skin": 1, "eye": 1}
        assert info["part_labels"][0] == {"label": "Wolf3D_Head/mat_skin", "part": "skin", "color": skin,
                                          "triangles": 1}
        assert info["part_labels"][1]["label"] == "Wolf3D_Head/Wolf3D_Eye"
    else:
        assert f"part: Wolf3D_Head/mat_skin (skin) {skin}, 1 triangles" in out.getvalue()


def test_every_skin_primitive_counts_as_skin_for_cloning():
    b = GltfBuilder()
    for k, name in enumerate(("Wolf3D_Skin", "Wolf3D_Body", "Wolf3D_Eye")):
        triangle_scene(b, positions=TRI + k, material={"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": [0.5 + k / 10, 0.4, 0.3, 1]}})
    b.doc["scenes"] = [{"nodes": [0, 1, 2]}]
    a = load_gltf(b.glb(), HERE, None, "avatar")
    assert [p.name for p in a.parts] == ["skin", "skin", "eye"]
    assert sorted(skin_faces(a).ravel().tolist()) == list(range(6))  # both skin triangles, not the eye
