"""The fap2d package on a synthetic face: schema, determinism, 2D FAT accuracy, layers, reference renderer."""

from __future__ import annotations

import io
import json
import types
import zipfile

import jsonschema
import numpy as np
import pytest
import reference_render
from scipy.ndimage import binary_dilation

from converter.animation import FaceAnimation
from converter.camera import Camera
from converter.errors import InputError
from converter.mpeg4 import fat2d
from converter.mpeg4.fap import read_fap
from converter.options import ConversionOptions
from converter.writers import fap2d
from player import flatten


def test_manifest_validates_and_arrays_fit(synthetic_package):
    pkg, data = synthetic_package
    schema = json.loads(fap2d.SCHEMA_PATH.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    z = zipfile.ZipFile(io.BytesIO(data))
    manifest = json.loads(z.read("manifest.json"))
    jsonschema.validate(manifest, schema)
    assert set(z.namelist()) == {"manifest.json", "portrait.png", "mouth.png", "data.bin", "stream.fap"}
    blob = z.read("data.bin")
    refs = [manifest["mesh"]["vertices"], manifest["mesh"]["triangles"]]
    refs += [e[k] for e in manifest["fat2d"]["faps"] for k in ("vertices", "displacements")]
    for r in refs:
        size = np.dtype("<" + r["dtype"]).itemsize * int(np.prod(r["shape"]))
        assert r["offset"] + size <= len(blob)
    n = manifest["mesh"]["vertices"]["shape"][0]
    tri = reference_render.load_package(data).triangles
    assert tri.min() >= 0 and tri.max() < n
    # A manifest that breaks the schema is caught by it.
    broken = dict(manifest, version="2.0")
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, schema)


@pytest.mark.slow
def test_package_is_deterministic(synthetic, synthetic_package, xface):
    anim, fdp, deform = synthetic
    stream = read_fap(xface / "joy.fap")
    again = fap2d.package(fat2d.build(anim, fdp, stream, deform, ConversionOptions(to="fap2d", size=256)))
    assert fap2d.package_zip(again) == synthetic_package[1]


def test_dropped_and_converted_faps(synthetic_package):
    m = synthetic_package[0].manifest
    dropped = {d["fap"]: d["reason"] for d in m["dropped"]}
    kinds = {e["fap"]: e["kind"] for e in m["fat2d"]["faps"]}
    for f in (14, 16, 17, 27, 28):
        assert "z-direction" in dropped[f]
    for f in (43, 44, 45, 46, 47):
        assert "tongue" in dropped[f]
    for f in (48, 49, 50):
        assert "head rotation" in dropped[f]
    assert kinds[23] == kinds[25] == "translate"
    assert kinds[3] == "vertices"
    assert not set(dropped) & set(kinds)
    assert set(dropped) | set(kinds) == set(range(1, 69))


def test_table_follows_projected_3d_displacement(synthetic, synthetic_package):
    """At and between the amplitudes, the 2D table lands where the 3D engine's projection does."""
    anim, fdp, deform = synthetic
    pkg = reference_render.load_package(synthetic_package[1])
    cam = Camera.from_json(pkg.manifest["camera"])
    neutral = anim.frames[0].astype(np.float64)
    # The package's vertices are a subset of the face's: match them by neutral projection.
    xy_all = cam.project(neutral)[0]
    d = np.linalg.norm(xy_all[None, :, :] - pkg.xy0[:, None, :], axis=-1)
    ids = d.argmin(axis=1)
    assert d.min(axis=1).max() <= fat2d.XY_STEP
    for fap, value in ((3, 157.5), (3, 500.0), (31, -300.0), (19, 700.0)):
        v = np.zeros(68)
        v[fap - 1] = value
        want = cam.project(deform(v[None])[0][ids].astype(np.float64))[0]
        got = reference_render.positions(pkg, v)
        err = np.abs(got - want).max()
        moved = np.abs(want - pkg.xy0).max()
        assert moved > 1.0, f"FAP {fap} should move the face"
        assert err <= 0.1 + 0.02 * moved, f"FAP {fap}={value}: 2D table off by {err:.3f} px (moved {moved:.1f})"


def test_eyeball_rotation_is_a_2d_translation(synthetic_package):
    pkg = reference_render.load_package(synthetic_package[1])
    v = np.zeros(68)
    v[22] = 20000  # yaw_l_eyeball, 0.2 rad
    delta = reference_render.positions(pkg, v) - pkg.xy0
    moved = np.abs(delta).max(axis=1) > 0
    assert 3 < moved.sum() < len(delta) // 4
    assert np.allclose(delta[moved], delta[moved][0]) and abs(delta[moved][0, 0]) > 1.0


def test_neutral_frame_equals_portrait(synthetic_package):
    pkg = reference_render.load_package(synthetic_package[1])
    frame = reference_render.render_frame(pkg, np.zeros(68))
    inside = pkg.portrait[..., 3] == 255
    assert inside.mean() > 0.3
    assert np.array_equal(frame[inside], pkg.portrait[inside])
    # On the anti-aliased silhouette the mesh layer adds to the portrait's coverage, never changes colour much.
    diff = np.abs(flatten(frame) - flatten(pkg.portrait)).max(axis=-1)
    edge = binary_dilation((pkg.portrait[..., 3] > 0) & (pkg.portrait[..., 3] < 255))
    assert diff.mean() < 0.5 and not (diff[~edge] > 2).any()


def test_jaw_open_moves_chin_down(synthetic_package):
    pkg = reference_render.load_package(synthetic_package[1])
    chin = np.array(pkg.manifest["feature_points"]["2.1"])
    k = int(np.linalg.norm(pkg.xy0 - chin, axis=1).argmin())
    v = np.zeros(68)
    v[2] = 600  # open_jaw
    xy = reference_render.positions(pkg, v)
    assert xy[k, 1] - chin[1] > 5.0 and abs(xy[k, 0] - chin[0]) < 0.5
    # The drawn chin goes lower: the silhouette's bottom under the mouth moves down.
    col = int(round(chin[0]))

    def bottom(img):
        return np.flatnonzero(img[:, col, 3] > 128).max()

    assert bottom(reference_render.render_frame(pkg, v)) - bottom(pkg.portrait) > 5
    # Opening the jaw shows the mouth layer between the lips.
    mouth = np.array(pkg.manifest["feature_points"]["2.3"])
    frame = reference_render.render_frame(pkg, v)
    assert pkg.mouth[..., 3].any()
    x, y = int(mouth[0]), int(mouth[1])
    assert not np.array_equal(frame[y - 2:y + 12, x - 3:x + 3], pkg.portrait[y - 2:y + 12, x - 3:x + 3])


def test_layers_and_feature_points(synthetic_package):
    pkg, _ = synthetic_package
    m = pkg.manifest
    assert [layer["name"] for layer in m["layers"]] == ["portrait", "mouth", "face"]
    assert m["layers"][1]["source"] == "render"  # the synthetic face has a teeth part
    fp = m["feature_points"]
    assert {"2.1", "2.2", "3.5", "3.6"} <= set(fp)
    assert fp["3.5"][0] > fp["3.6"][0]  # the face's left eye is on the image's right, seen from the front
    assert fp["2.1"][1] > fp["2.2"][1] > fp["3.5"][1]


def test_default_mouth_layer_without_teeth(synthetic, xface):
    """A face with no teeth or tongue gets a default mouth pattern placed at its lip feature points."""
    anim, fdp, deform = synthetic
    keep = anim.part_ids != 2
    bare = FaceAnimation(anim.frames, anim.faces[keep], anim.part_ids[keep], anim.parts, anim.fps, "bare")
    fdp2 = types.SimpleNamespace(points=fdp.points, parts={k: v for k, v in fdp.parts.items() if "teeth" not in k},
                                 fapu=fdp.fapu)
    stream = read_fap(xface / "anger.fap")
    pkg = fap2d.package(fat2d.build(bare, fdp2, stream, deform, ConversionOptions(to="fap2d", size=128)))
    assert pkg.manifest["layers"][1]["source"] == "default"
    mouth = reference_render._image(pkg.files["mouth.png"])
    ys, xs = np.nonzero(mouth[..., 3])
    lips = np.array([pkg.manifest["feature_points"][k] for k in ("8.3", "8.4")])
    assert lips[:, 0].min() - 2 <= xs.min() and xs.max() <= lips[:, 0].max() + 2
    assert ys.min() < lips[:, 1].mean() < ys.max()


def test_animation_bytes_reported(synthetic_package):
    sizes = fap2d.animation_sizes(synthetic_package[0])
    assert 0 < sizes["stream_deflated_bytes_per_s"] < sizes["stream_bytes_per_s"]


@pytest.mark.parametrize("case", ["not-zip", "no-manifest", "short-data"])
def test_reference_renderer_refuses_a_broken_package(case, synthetic_package):
    pkg, data = synthetic_package
    if case == "not-zip":
        bad = b"PK\x03\x04 but not really a zip"
    else:
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as z:
            for name, body in pkg.files.items():
                if case == "no-manifest" and name == "manifest.json":
                    continue
                z.writestr(name, body[:64] if (case == "short-data" and name == "data.bin") else body)
        bad = out.getvalue()
    with pytest.raises(InputError):
        reference_render.load_package(bad)
