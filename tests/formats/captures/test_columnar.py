"""didimo per-shape columns JSON: columns checked against frameCount, Unity Euler degrees as yaw/pitch/roll."""

from __future__ import annotations

import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import columnar
from tests.formats.captures.layout_samples import read

FIXTURE = "didimo_poses.json"


def test_the_fixture_reads_column_by_column():
    doc = json.loads(read(FIXTURE))
    track = columnar.parse(read(FIXTURE), FIXTURE)
    assert track.names == list(doc["poses"]) and track.n_frames == doc["frameCount"] == 20
    assert track.fps == 30.0 and track.duration == pytest.approx(doc["animationLength"])
    for j, name in enumerate(track.names):
        np.testing.assert_allclose(track.values[:, j], doc["poses"][name], atol=1e-7)
    # Quaternion.Euler(x, y, z): x pitch, y yaw, z roll, in degrees
    head = np.array(doc["skeleton"]["headRotation"])
    np.testing.assert_allclose(track.head, np.radians(head[:, [1, 0, 2]]), atol=1e-6)
    eye = np.array(doc["skeleton"]["rightEyeRotation"])
    np.testing.assert_allclose(track.eye_right[:, 0], np.radians(eye[:, 1]), atol=1e-6)


def test_timestamps_and_missing_fps():
    doc = {"source": "ARKit", "poses": {"jawOpen": [0, 0.5, 1]}, "frameCount": 3, "animationLength": 0.1,
           "timestamps": [0.0, 0.05, 0.1]}
    track = columnar.parse(json.dumps(doc).encode(), "c.json")
    assert track.fps == 20.0 and track.times.tolist() == pytest.approx([0, 0.05, 0.1]) and track.head is None


@pytest.mark.parametrize("change,words", [
    ({"frameCount": 21}, ["jawOpen", "20 values", "frameCount is 21"]),
    ({"frameCount": "20"}, ["frameCount", "whole number"]),
    ({"poses": {}}, ["poses", "empty"]),
    ({"skeleton": {"headRotation": [[0, 0, 0]]}}, ["headRotation", "1 frames"]),
    ({"timestamps": [0.0] * 20}, ["frame 1 is not later"]),
])
def test_truncated_or_broken_files(change, words):
    doc = {**json.loads(read(FIXTURE)), **change}
    with pytest.raises(InputError) as err:
        columnar.parse(json.dumps(doc).encode(), "c.json")
    assert str(err.value).startswith("c.json") and all(w in str(err.value) for w in words), str(err.value)


def test_sniff():
    assert columnar.sniff(read(FIXTURE))
    assert not columnar.sniff(b'{"poses": [1, 2]}')
    assert not columnar.sniff(read("mediapipe_video.json"))
