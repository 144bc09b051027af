"""glTF animation choice: the per-node split take plays together, --animation NAME|INDEX|all, info lists clips."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats import load
from converter.formats.gltf import load_gltf
from tests.formats.helpers import TRI, add_track, triangle_scene

HERE = Path(".")


def two_node_scene():
    """Two triangles on nodes a and b (returned), both in scene 0."""
    b, a = triangle_scene(node={"name": "a"})
    _, c = triangle_scene(b, node={"name": "b"})
    b.doc["scenes"] = [{"nodes": [a, c]}]
    return b, a, c


def z_quat(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(h), math.cos(h)]


def test_per_node_split_take_plays_together_without_a_note():
    b, a, c = two_node_scene()
    add_track(b, a, "translation", [0, 1], [[0, 0, 0], [2, 0, 0]], anim=0, name="a_take")
    add_track(b, c, "rotation", [0, 1], [z_quat(0), z_quat(90)], anim=1, name="b_take")
    anim = load_gltf(b.glb(), HERE, 2.0, "split")
    assert anim.n_frames == 3
    # node a (vertices 0..2) slides 2 along x; node b (3..5) turns 90 degrees about z: (1,0,0) -> (0,1,0).
    np.testing.assert_allclose(anim.frames[:, 0], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], atol=1e-6)
    np.testing.assert_allclose(anim.frames[2, 4], [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(anim.frames[1, 4], [math.sqrt(0.5), math.sqrt(0.5), 0], atol=1e-6)
    assert "warnings" not in anim.extras
    assert anim.extras["animated_nodes"] == ["a", "b"]


def clips_on_one_node():
    """Animations idle (1 s, x to 1), walk (2 s, x to 4), hop (1 s, y to 3), all on node a; b stays."""
    b, a, c = two_node_scene()
    add_track(b, a, "translation", [0, 1], [[0, 0, 0], [1, 0, 0]], anim=0, name="idle")
    add_track(b, a, "translation", [0, 2], [[0, 0, 0], [4, 0, 0]], anim=1, name="walk")
    add_track(b, a, "translation", [0, 1], [[0, 0, 0], [0, 3, 0]], anim=2, name="hop")
    return b


def test_clips_on_the_same_node_play_the_first_with_a_note_naming_the_others():
    anim = load_gltf(clips_on_one_node().glb(), HERE, 4.0, "rig")
    assert anim.n_frames == 5 and anim.extras["animation"] == "idle"
    np.testing.assert_allclose(anim.frames[-1, 0], [1, 0, 0], atol=1e-6)
    (note,) = anim.extras["warnings"]
    assert "idle" in note and "1 'walk'" in note and "2 'hop'" in note and "--animation" in note


@pytest.mark.parametrize("choice,frames,last", [("walk", 9, [4, 0, 0]), ("1", 9, [4, 0, 0]), ("2", 5, [0, 3, 0]),
                                                ("hop", 5, [0, 3, 0])])
def test_a_clip_chosen_by_name_or_index_plays_alone(choice, frames, last):
    anim = load_gltf(clips_on_one_node().glb(), HERE, 4.0, "rig", animation=choice)
    assert anim.n_frames == frames and "warnings" not in anim.extras
    np.testing.assert_allclose(anim.frames[-1, 0], last, atol=1e-6)
    np.testing.assert_allclose(anim.frames[:, 3:], np.broadcast_to(TRI, (frames, 3, 3)), atol=1e-6)  # b stays


def test_all_plays_every_take_one_after_another_each_from_rest():
    anim = load_gltf(clips_on_one_node().glb(), HERE, 4.0, "rig", animation="all")
    assert anim.n_frames == 5 + 9 + 5
    x, y = anim.frames[:, 0, 0], anim.frames[:, 0, 1]
    np.testing.assert_allclose(x[:5], [0, 0.25, 0.5, 0.75, 1], atol=1e-6)
    np.testing.assert_allclose(x[5:14], np.arange(9) * 0.5, atol=1e-6)
    np.testing.assert_allclose(x[14:], 0, atol=1e-6)  # hop does not animate x: the rest value, not walk's end
    np.testing.assert_allclose(y[14:], [0, 0.75, 1.5, 2.25, 3], atol=1e-6)


@pytest.mark.parametrize("choice", ["run", "3", "-1"])
def test_an_unknown_clip_is_one_input_error_listing_the_clips(choice):
    with pytest.raises(InputError, match="no animation .*0 'idle', 1 'walk', 2 'hop', or all"):
        load_gltf(clips_on_one_node().glb(), HERE, 4.0, "rig", animation=choice)


def test_animation_on_a_still_or_a_non_gltf_input_is_refused(tmp_path):
    b, _ = triangle_scene()
    with pytest.raises(InputError, match="has no animations"):
        load_gltf(b.glb(), HERE, None, "still", animation="walk")
    assert load_gltf(b.glb(), HERE, None, "still", animation="all").n_frames == 1
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="not glTF"):
        load(obj, animation="0")


def test_morph_stress_test_every_clip_selectable(shared_data):
    path = shared_data / "real" / "MorphStressTest.gltf"
    default = load(path)
    summary = default.extras["animations"]
    assert [c["name"] for c in summary] == ["Individuals", "Pulse", "TheWave"]
    assert all(c["channels"] == 1 and c["targets"] == ["Main.weights"] for c in summary)
    assert "Pulse" in default.extras["warnings"][0] and "TheWave" in default.extras["warnings"][0]
    seen = []
    for clip in summary:
        anim = load(path, animation=clip["name"])
        assert anim.fps == 24.0
        assert anim.n_frames == math.floor(clip["duration"] * 24 + 1e-3) + 1
        motion = np.abs(anim.frames - anim.frames[:1]).max()
        assert motion > 0.05  # the weights move the mesh
        seen.append(anim.frames)
    assert seen[0].shape != seen[1].shape or not np.allclose(seen[0], seen[1])
    everything = load(path, animation="all")
    assert everything.n_frames == sum(s.shape[0] for s in seen)
    np.testing.assert_allclose(everything.frames[:len(seen[0])], seen[0])


def test_info_lists_every_clip_and_the_note(tmp_path):
    path = tmp_path / "rig.glb"
    path.write_bytes(clips_on_one_node().glb())
    r = subprocess.run([sys.executable, "-m", "converter.cli", "info", str(path), "--json"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert [(c["name"], c["duration"], c["channels"], c["targets"]) for c in info["animations"]] == [
        ("idle", 1.0, 1, ["a.translation"]), ("walk", 2.0, 1, ["a.translation"]), ("hop", 1.0, 1, ["a.translation"])]
    assert "walk" in info["warnings"][0]
    r = subprocess.run([sys.executable, "-m", "converter.cli", "info", str(path), "--animation", "run"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "no animation 'run'" in r.stderr and "Traceback" not in r.stderr
    text = subprocess.run([sys.executable, "-m", "converter.cli", "info", str(path)], capture_output=True,
                          text=True, timeout=120).stdout
    assert "1 walk: 2.0 s, 1 channels, targets a.translation" in text


def test_conversion_report_carries_the_loader_note(tmp_path):
    from converter.convert import convert
    from converter.options import ConversionOptions

    path = tmp_path / "rig.glb"
    path.write_bytes(clips_on_one_node().glb())
    result = convert(path, ConversionOptions(size=64, fps=4.0))
    assert any("1 'walk'" in w for w in result.report.warnings)
    chosen = convert(path, ConversionOptions(size=64, fps=4.0, animation="walk"))
    assert not any("walk" in w for w in chosen.report.warnings)
    assert chosen.report.counts["frames"] == 9 and result.report.counts["frames"] == 5
