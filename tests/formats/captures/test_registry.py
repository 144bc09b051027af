"""The capture registry: every layout recognised by content from its fixture, one clear error otherwise."""

from __future__ import annotations

import json

import pytest

from converter.errors import InputError
from converter.formats import captures
from converter.formats.weights import is_capture as facade_is_capture
from converter.formats.weights import parse_weights
from converter.options import option_fields
from tests.formats.captures import layout_samples

# fixture in tests/data/captures -> the layout that must read it (H1b's fixtures from layout_samples.OWNERS)
OWNERS = {
    "livelinkface_myslate3_cut.csv": "livelinkface-csv",
    "facecap_sample.txt": "facecap-txt",
    "didimo_poses.json": "columnar-json",
    "mediapipe_blendshapes_people.json": "mediapipe-json",
    "mediapipe_blendshapes_flat.json": "mediapipe-json",
    "mediapipe_video.json": "mediapipe-json",
    "ifacialmocap_frame.txt": "ifacialmocap-txt",
    "ifacialmocap_frame_extra_key.txt": "ifacialmocap-txt",
    **layout_samples.OWNERS,
}
FRAMES_JSON = b'[{"time": 0.0, "blendshapes": {"jawOpen": 0.1}}, {"time": 0.5, "blendshapes": {"jawOpen": 0.4}}]'


@pytest.mark.parametrize("fixture", sorted(OWNERS))
def test_each_fixture_is_read_by_its_layout(fixture):
    data = layout_samples.read(fixture)
    layout = captures.detect(data)
    assert layout is not None and layout.name == OWNERS[fixture]
    track = captures.parse_capture(data, fixture)
    assert track.source == OWNERS[fixture]
    assert track.n_frames >= 1 and len(track.names) == track.values.shape[1] > 0
    assert track.times.shape == (track.n_frames,) and track.times[0] == 0.0
    assert captures.is_capture(data) is not None


def test_every_registered_layout_has_a_fixture_or_sample():
    covered = set(OWNERS.values()) | {"frames-json"}
    assert {layout.name for layout in captures.LAYOUTS} == covered
    assert captures.detect(FRAMES_JSON).name == "frames-json"


def test_layout_names_are_unique_and_documented():
    names = [layout.name for layout in captures.LAYOUTS]
    assert len(set(names)) == len(names)
    assert all(layout.doc and layout.label and layout.extensions for layout in captures.LAYOUTS)
    assert captures.layout_named("facecap-txt").label == "Face Cap TXT"
    with pytest.raises(InputError, match="unknown capture layout"):
        captures.layout_named("nope")


@pytest.mark.parametrize("data", [
    b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    b'{"asset": {"version": "2.0"}, "meshes": []}',
    b"ply\nformat ascii 1.0\n",
    b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR",
])
def test_a_file_no_layout_reads_is_one_error_naming_the_users_file(data):
    assert captures.detect(data) is None and captures.is_capture(data) is None
    with pytest.raises(InputError) as err:
        captures.parse_capture(data, "my face.obj")
    msg = str(err.value)
    assert msg.startswith("my face.obj is not a weight layout facesvg knows")
    assert "Live Link Face CSV" in msg and "Face Cap TXT" in msg and "MediaPipe" in msg
    assert msg.count(". ") == 0 and msg.endswith(".")


@pytest.mark.parametrize("data,words", [
    (b"", ["take.json", "empty"]),
    (b"  \n", ["take.json", "empty"]),
    (b'{"frames": [', ["take.json", "not valid JSON"]),
    (b"[1, 2", ["take.json", "not valid JSON"]),
])
def test_empty_or_broken_files_say_so(data, words):
    with pytest.raises(InputError) as err:
        captures.parse_capture(data, "take.json")
    assert all(w in str(err.value) for w in words), str(err.value)


def test_a_refusal_inside_a_layout_names_the_users_file():
    bad = layout_samples.read("facecap_sample.txt").replace(b"k,0,", b"k,zero,", 1)
    with pytest.raises(InputError, match=r"^session 3\.txt line 2 holds a value that is not a number\.$"):
        captures.parse_capture(bad, "session 3.txt")


def test_extensions_are_every_layouts_suffixes_sorted_and_unique():
    ext = captures.extensions()
    assert list(ext) == sorted(set(ext))
    assert all(e.startswith(".") and e == e.lower() for e in ext)
    assert set(ext) == {e.lower() for layout in captures.LAYOUTS for e in layout.extensions}
    assert {".csv", ".json", ".txt"} <= set(ext)


def test_read_capture_reads_files_and_refuses_missing_ones(tmp_path):
    path = tmp_path / "take.json"
    path.write_bytes(FRAMES_JSON)
    track = captures.read_capture(path)
    assert track.n_frames == 2 and track.names == ["jawOpen"]
    with pytest.raises(InputError, match="does not exist"):
        captures.read_capture(tmp_path / "nope.csv")


def test_the_weights_facade_is_the_registry():
    data = layout_samples.read("facecap_sample.txt")
    assert parse_weights(data, "f.txt").source == "facecap-txt"
    assert facade_is_capture(layout_samples.read("livelinkface_myslate3_cut.csv")) == "a Live Link Face capture CSV"
    assert facade_is_capture(layout_samples.read("facecap_sample.txt")) == "a Face Cap TXT capture"


def test_describe_says_layout_frames_rate_and_angles():
    track = captures.parse_capture(layout_samples.read("livelinkface_myslate3_cut.csv"), "take.csv")
    info = captures.describe(track)
    assert info["layout"] == "Live Link Face CSV" and info["source"] == "livelinkface-csv"
    assert info["frames"] == 24 and info["fps"] == 60.0 and info["names"] == 52
    assert info["duration"] == pytest.approx(track.times[-1] + 1 / 60, abs=1e-4)
    assert info["start_timecode"] == "00:32:09:07.867"
    assert info["eye_rotation"] is True and info["head_rotation"] is False  # the take's head columns are all 0
    info = captures.describe(captures.parse_capture(layout_samples.read("facecap_sample.txt"), "f.txt"))
    assert info["head_rotation"] is True and info["frames"] == 40 and info["fps"] == 30.0


def test_a_gltf_document_is_never_taken_for_a_capture():
    # glTF meshes carry "weights" and animations "time"-like keys: the frame-list sniff alone would claim them
    doc = {"asset": {"version": "2.0"}, "meshes": [{"weights": [0.0, 1.0], "primitives": []}],
           "frames": [{"time": 0.0, "weights": {"jawOpen": 1.0}}]}
    data = json.dumps(doc).encode()
    assert captures.detect(data) is None and captures.is_capture(data) is None
    assert captures.detect(json.dumps({"frames": doc["frames"]}).encode()).name == "frames-json"


def test_the_weights_option_accepts_what_the_registry_reads():
    meta = next(f for f in option_fields() if f.name == "weights").meta
    assert tuple(sorted(meta.accept.split(","))) == captures.extensions()
