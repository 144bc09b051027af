"""Base-colour textures sampled at the vertices; vertex colours win; undecodable textures fall back with a note."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from converter.export.gltf_builder import ARRAY_BUFFER
from converter.formats import load
from converter.formats.gltf import load_gltf
from tests.formats.helpers import linear, srgb, triangle_scene

HERE = Path(".")
# A 2 x 2 texture: red, green / blue, white. UV (0, 0) is the image's top-left corner.
PIXELS = np.uint8([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]])
UV_AT_CENTRES = np.float32([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75]])  # red, green, blue texel centres


def png(pixels: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, format="PNG")
    return buf.getvalue()


def textured_triangle(image: dict | None = None, factor=None, colors=None, texture_extensions=None):
    b, n = triangle_scene()
    prim = b.doc["meshes"][0]["primitives"][0]
    prim["attributes"]["TEXCOORD_0"] = b.accessor(UV_AT_CENTRES, target=ARRAY_BUFFER)
    if colors is not None:
        prim["attributes"]["COLOR_0"] = b.accessor(np.float32(colors), target=ARRAY_BUFFER)
    if image is None:
        image = {"bufferView": b.view(png(PIXELS)), "mimeType": "image/png"}
    texture = {"source": b.add("images", image), "sampler": b.add("samplers", {"wrapS": 33071, "wrapT": 33071})}
    if texture_extensions is not None:
        texture = {"extensions": texture_extensions(b)}
    pbr: dict = {"baseColorTexture": {"index": b.add("textures", texture)}}
    if factor is not None:
        pbr["baseColorFactor"] = factor
    prim["material"] = b.add("materials", {"name": "Skin", "pbrMetallicRoughness": pbr})
    return b


def test_texture_colours_reach_the_vertices_and_the_triangle():
    anim = load_gltf(textured_triangle().glb(), HERE, None, "tex")
    assert [p.color for p in anim.parts] == [(1.0, 1.0, 1.0)]
    np.testing.assert_allclose(anim.face_base_colors(), [[1, 0, 0], [0, 1, 0], [0, 0, 1]], atol=1e-6)
    np.testing.assert_allclose(anim.triangle_colors(), [[1 / 3, 1 / 3, 1 / 3]], atol=1e-6)
    assert "warnings" not in anim.extras


def test_texture_between_texel_centres_is_bilinear_and_times_the_factor():
    b = textured_triangle(factor=[0.5, 1, 1, 1])
    uv = np.float32([[0.5, 0.25], [0.25, 0.5], [0.5, 0.5]])  # red|green, red/blue, the middle of all four
    b.doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = b.accessor(uv, target=ARRAY_BUFFER)
    anim = load_gltf(b.glb(), HERE, None, "tex")
    # Texels are sRGB: decoded to linear, filtered, times the linear factor, then encoded for display (glTF 2.0).
    want = srgb(np.array([[0.5, 0.5, 0], [0.5, 0, 0.5], [0.5, 0.5, 0.5]]) * [0.5, 1, 1])
    np.testing.assert_allclose(anim.face_base_colors(), want, atol=1e-6)
    np.testing.assert_allclose(anim.parts[0].color, srgb([0.5, 1, 1]), atol=1e-6)


def test_texture_of_a_known_srgb_colour_round_trips_times_the_factor():
    b = textured_triangle()
    b.doc["images"][0] = {"bufferView": b.view(png(np.full((2, 2, 3), [200, 100, 50], np.uint8))),
                          "mimeType": "image/png"}
    np.testing.assert_allclose(load_gltf(b.glb(), HERE, None, "tex").face_base_colors(),
                               np.tile([200 / 255, 100 / 255, 50 / 255], (3, 1)), atol=1e-5)
    b.doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.5, 0.5, 0.5, 1]
    want = srgb(0.5 * linear(np.array([200, 100, 50]) / 255))
    np.testing.assert_allclose(load_gltf(b.glb(), HERE, None, "tex").face_base_colors(), np.tile(want, (3, 1)),
                               atol=1e-5)


def test_vertex_colours_win_over_the_texture():
    anim = load_gltf(textured_triangle(colors=[[0.2, 0.2, 0.2]] * 3).glb(), HERE, None, "tex")
    np.testing.assert_allclose(anim.face_base_colors(), srgb(0.2), atol=1e-6)  # COLOR_0 is linear


def test_ktx2_texture_falls_back_to_the_factor_with_a_note():
    def basisu(b):
        b.use_extension("KHR_texture_basisu")
        ktx = b.add("images", {"bufferView": b.view(b"\xabKTX 20\xbb\r\n\x1a\n" + bytes(64)), "mimeType": "image/ktx2"})
        return {"KHR_texture_basisu": {"source": ktx}}

    anim = load_gltf(textured_triangle(factor=[0.2, 0.4, 0.6, 1], texture_extensions=basisu).glb(), HERE, None, "ktx")
    np.testing.assert_allclose(anim.parts[0].color, srgb([0.2, 0.4, 0.6]), atol=1e-6)
    assert anim.vertex_colors is None
    (note,) = anim.extras["warnings"]
    assert "image/ktx2" in note and "cannot be decoded" in note and "base colour" in note


def test_missing_image_file_falls_back_with_a_note(tmp_path):
    b = textured_triangle(image={"uri": "face_albedo.png"})
    anim = load_gltf(b.glb(), tmp_path, None, "tex")
    assert anim.vertex_colors is None and "face_albedo.png" in anim.extras["warnings"][0]
    (tmp_path / "face_albedo.png").write_bytes(png(PIXELS))
    anim = load_gltf(b.glb(), tmp_path, None, "tex")
    np.testing.assert_allclose(anim.face_base_colors()[0], [1, 0, 0], atol=1e-6)


def test_fox_keeps_its_texture_colours(shared_data):
    from converter.formats.gltf import parse_container
    from converter.formats.gltf.scene import _Document

    path = shared_data / "real" / "Fox.glb"
    anim = load(path)
    doc, chunk = parse_container(path.read_bytes())
    d = _Document(doc, chunk, path.parent, "fox")
    image = Image.open(io.BytesIO(bytes(d.view(doc["images"][0]["bufferView"])))).convert("RGB")
    uv = d.accessor(doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"])
    # Independent lookup: Pillow's nearest texel at each vertex; our bilinear sample stays close to it mostly.
    w, h = image.size
    nearest = np.array([image.getpixel((min(int(u * w), w - 1), min(int(v * h), h - 1))) for u, v in uv]) / 255
    colours = anim.vertex_colors
    assert colours is not None and len(colours) == len(nearest)
    assert np.median(np.abs(colours - nearest).max(axis=1)) < 0.05
    mean = colours.mean(0)
    assert mean[0] > mean[1] > mean[2]  # an orange fox
    assert (np.abs(colours - colours[0]).max(axis=1) > 0.3).any()  # more than one colour: the tail tip, the legs
