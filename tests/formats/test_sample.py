"""The bundled sample and its gltfpack-style twin: counts, motion, ICT coordinates, determinism."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from converter.formats import load
from converter.formats.gltf import parse_container

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sample(sample_path):
    return load(sample_path)


@pytest.fixture(scope="module")
def twin(sample_path):
    return load(sample_path.with_name("face_gltfpack.glb"))


def test_sample_counts_parts_and_facts(sample, sample_path):
    assert sample_path.stat().st_size <= 400_000
    assert (sample.n_frames, sample.fps) == (121, 30.0)
    assert 2800 <= sample.n_faces <= 3200
    assert [p.name for p in sample.parts] == ["skin", "mouth", "teeth", "eye", "iris", "eye", "iris"]
    assert [p.label for p in sample.parts] == ["face/Skin", "face/MouthInterior", "face/Teeth",
                                               "eye_left_mesh/EyeSclera", "eye_left_mesh/Iris",
                                               "eye_right_mesh/EyeSclera", "eye_right_mesh/Iris"]
    assert np.all(np.bincount(sample.part_ids) > 100)
    assert len(sample.extras["morph_targets"]) >= 8 and "jawOpen" in sample.extras["morph_targets"]
    assert sample.extras["animated_nodes"] == ["eye_left", "eye_right", "head"]
    assert sample.extras["source_fps"] == 30.0


def test_twin_is_gltfpack_style_and_matches_within_quantisation(sample, twin, sample_path):
    packed = sample_path.with_name("face_gltfpack.glb").read_bytes()
    assert len(packed) <= 250_000
    doc, _ = parse_container(packed)
    assert set(doc["extensionsRequired"]) == {"KHR_mesh_quantization", "EXT_meshopt_compression"}
    assert all("EXT_meshopt_compression" in bv.get("extensions", {}) for bv in doc["bufferViews"])
    assert (twin.n_frames, twin.n_vertices, twin.n_faces) == (sample.n_frames, sample.n_vertices, sample.n_faces)
    assert [p.name for p in twin.parts] == [p.name for p in sample.parts]
    # 14-bit positions over a ~30 cm head, 12-bit rotations: well under a millimetre everywhere.
    assert np.abs(twin.frames - sample.frames).max() < 0.05


def test_frame_zero_is_the_ict_head_in_its_own_units(sample, shared_data):
    from converter.formats.ictfacekit import load_ict_head

    head = load_ict_head(shared_data / "ict_facekit")
    dist, _ = cKDTree(head.vertices).query(sample.frames[0])
    assert dist.max() < 1e-4


def test_sequence_moves_jaw_eyelids_and_eyes(sample):
    f = sample.frames
    skin = np.unique(sample.faces[sample.part_ids == 0])
    # Jaw open (peak near 2.2 s): the lower lip, below the nose and in front, drops by centimetres.
    drop = f[66, skin, 1] - f[0, skin, 1]
    lip = skin[np.argmin(drop)]
    assert drop.min() < -2.0 and f[0, lip, 1] < 0 and f[0, lip, 2] > 10
    # Blink (peak near 1.12 s): an upper eyelid, at eye height, closes by about a centimetre in 0.2 s.
    lid = f[34, skin, 1] - f[28, skin, 1]
    assert lid.min() < -0.7 and 2 < f[0, skin[np.argmin(lid)], 1] < 6
    # Eyes: rigid rotation about their centre (distances kept) but positions change between saccades.
    iris = np.unique(sample.faces[sample.part_ids == 4])
    iris = iris[f[0, iris, 0] > 0]  # the left eye only: one rigid body
    assert np.abs(f[30, iris] - f[0, iris]).max() > 0.2
    centred = f[:, iris] - f[:, iris].mean(1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(centred, axis=2)[30], np.linalg.norm(centred, axis=2)[0], atol=1e-4)


def _same_structure(built, committed, path: str = "") -> None:
    """Same glTF JSON tree: keys, lengths, strings, ints; floats within 1e-5 (relative above 1); byte layout free."""
    if isinstance(committed, dict):
        assert isinstance(built, dict) and built.keys() == committed.keys(), path
        for key in committed:
            if key not in ("byteLength", "byteOffset"):  # follow the (compressed) data sizes
                _same_structure(built[key], committed[key], f"{path}/{key}")
    elif isinstance(committed, list):
        assert isinstance(built, list) and len(built) == len(committed), path
        for k, (b, c) in enumerate(zip(built, committed)):
            _same_structure(b, c, f"{path}/{k}")
    elif isinstance(committed, float) or isinstance(built, float):
        assert abs(built - committed) <= 1e-5 * max(1.0, abs(committed)), (path, built, committed)
    elif isinstance(committed, int) and path.rsplit("/", 2)[-2] in ("min", "max"):
        assert abs(built - committed) <= 1, (path, built, committed)  # quantized bounds: one step of rounding
    else:
        assert built == committed, (path, built, committed)


@pytest.mark.slow
def test_make_sample_is_deterministic_and_matches_the_committed_files(shared_data, sample_path, tmp_path):
    # Byte-for-byte within one environment; against the committed files, the same asset within float noise:
    # the bytes follow meshoptimizer's, numpy's and scipy's last bits, which are not pinned.
    spec = importlib.util.spec_from_file_location("make_sample", ROOT / "samples" / "make_sample.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from converter.formats.ictfacekit import load_ict_head

    head = load_ict_head(shared_data / "ict_facekit")
    for quantized, name in ((False, "face.glb"), (True, "face_gltfpack.glb")):
        built = mod.build(head, quantized)
        assert mod.build(head, quantized) == built, f"{name}: make_sample.py is not deterministic"
        committed = sample_path.with_name(name).read_bytes()
        doc, _ = parse_container(committed)
        _same_structure(parse_container(built)[0], doc)
        (tmp_path / name).write_bytes(built)
        a, b = load(tmp_path / name), load(sample_path.with_name(name))
        np.testing.assert_array_equal(a.faces, b.faces)
        np.testing.assert_array_equal(a.part_ids, b.part_ids)
        assert [p.name for p in a.parts] == [p.name for p in b.parts]
        assert a.extras["morph_targets"] == b.extras["morph_targets"]
        # Positions within 1e-5 cm; the twin's may also round to the next 14-bit step on each axis (then rotated).
        step = max(max(n.get("scale", [0.0])) for n in doc["nodes"]) if quantized else 0.0
        np.testing.assert_allclose(a.frames, b.frames, rtol=0, atol=1e-5 + 2 * step)
