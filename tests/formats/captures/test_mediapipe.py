"""MediaPipe FaceLandmarker blendshapes: the two real app layouts, a timed recording, _neutral dropped."""

from __future__ import annotations

import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import mediapipe
from tests.formats.captures.layout_samples import read


def test_the_people_layout():
    doc = json.loads(read("mediapipe_blendshapes_people.json"))
    track = mediapipe.parse(read("mediapipe_blendshapes_people.json"), "p.json")
    cats = doc["people"][0]
    assert cats[0]["name"] == "_neutral" and "_neutral" not in track.names
    assert track.names == [c["name"] for c in cats[1:]] and len(track.names) == 51
    np.testing.assert_allclose(track.values[0], [c["score"] for c in cats[1:]], rtol=1e-6)
    assert track.n_frames == 1 and "tongueOut" not in track.names


def test_the_flat_layout_with_string_scores():
    doc = json.loads(read("mediapipe_blendshapes_flat.json"))
    track = mediapipe.parse(read("mediapipe_blendshapes_flat.json"), "f.json")
    assert track.names == [c["category_name"] for c in doc[1:]]
    np.testing.assert_allclose(track.values[0], [float(c["score"]) for c in doc[1:]], rtol=1e-6)


def test_a_recorded_video():
    doc = json.loads(read("mediapipe_video.json"))
    track = mediapipe.parse(read("mediapipe_video.json"), "v.json")
    assert track.n_frames == 15 and track.fps == 30.0
    np.testing.assert_allclose(track.times, [(f["timestampMs"] - doc[0]["timestampMs"]) / 1000 for f in doc])
    jaw = [next(c["score"] for c in f["faceBlendshapes"][0]["categories"] if c["categoryName"] == "jawOpen")
           for f in doc]
    np.testing.assert_allclose(track.values[:, track.names.index("jawOpen")], jaw, rtol=1e-6)


def test_python_layout_and_wrapped_frames():
    cats = [{"index": 0, "score": 0.9, "category_name": "_neutral"}, {"index": 1, "score": 0.3, "category_name": "a"}]
    track = mediapipe.parse(json.dumps({"face_blendshapes": [cats]}).encode(), "r.json")
    assert track.names == ["a"] and track.values[0, 0] == pytest.approx(0.3)
    frames = {"fps": 25, "frames": [{"time": k / 25, "blendshapes": cats} for k in range(3)]}
    track = mediapipe.parse(json.dumps(frames).encode(), "w.json")
    assert track.fps == 25.0 and track.times[2] == pytest.approx(0.08)


@pytest.mark.parametrize("doc,words", [
    ({"faceBlendshapes": []}, ["found no face"]),
    ([{"categoryName": "_neutral", "score": 1.0}], ["only _neutral"]),
    ([{"categoryName": "a", "score": "high"}], ["'a'", "not a finite number"]),
    ([{"timestampMs": 5, "blendshapes": [{"categoryName": "a", "score": 1}]},
      {"timestampMs": 5, "blendshapes": [{"categoryName": "a", "score": 1}]}], ["frame 1 is not later"]),
])
def test_bad_results(doc, words):
    with pytest.raises(InputError) as err:
        mediapipe.parse(json.dumps(doc).encode(), "m.json")
    assert str(err.value).startswith("m.json") and all(w in str(err.value) for w in words), str(err.value)


@pytest.mark.shared
def test_the_real_files_are_the_fixtures(shared_data):
    for name in ("mediapipe_blendshapes_people.json", "mediapipe_blendshapes_flat.json"):
        assert (shared_data / "real" / name).read_bytes() == read(name)
