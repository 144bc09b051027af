"""Per-frame weight JSON: frame lists (seconds or millisecond stamps), wrapped lists, time-keyed objects."""

from __future__ import annotations

import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import framesjson


def parse(doc) -> object:
    return framesjson.parse(json.dumps(doc).encode(), "f.json")


def test_frame_list_with_seconds_measures_its_rate():
    frames = [{"time": k / 25, "blendshapes": {"jawOpen": k / 10, "eyeBlink_L": 1 - k / 10}} for k in range(6)]
    track = parse(frames)
    assert track.names == ["jawOpen", "eyeBlink_L"] and track.fps == 25.0
    np.testing.assert_allclose(track.values[:, 0], np.arange(6) / 10, atol=1e-7)
    np.testing.assert_allclose(track.times, np.arange(6) / 25)


def test_millisecond_stamps_and_lists_of_named_entries():
    frames = [{"timestamp": 5000 + 40 * k, "weights": [{"name": "jawOpen", "value": 0.2 * k}]} for k in range(4)]
    track = parse(frames)
    assert track.times[1] == pytest.approx(0.04) and track.fps == 25.0
    assert track.values[3, 0] == pytest.approx(0.6)


def test_wrapped_and_time_keyed():
    track = parse({"fps": 30, "frames": [{"blendshapes": {"jawOpen": 0.5}}] * 3})
    assert track.fps == 30.0 and track.times[2] == pytest.approx(2 / 30)
    track = parse({"0.5": {"jawOpen": 0.4}, "0.0": {"jawOpen": 0.2}})
    assert track.times.tolist() == [0.0, 0.5] and track.values[:, 0].tolist() == pytest.approx([0.2, 0.4])


def test_names_missing_in_some_frames_are_zero_there():
    track = parse([{"time": 0, "blendshapes": {"a": 1.0}}, {"time": 0.1, "blendshapes": {"b": 0.5}}])
    assert track.names == ["a", "b"] and track.values.tolist() == [[1.0, 0.0], [0.0, 0.5]]


@pytest.mark.parametrize("doc,words", [
    ([{"time": 0, "blendshapes": {"jawOpen": "x"}}], ["jawOpen", "not a finite number"]),
    ([{"time": 0.1, "blendshapes": {"a": 1}}, {"time": 0.1, "blendshapes": {"a": 1}}], ["not increasing"]),
    ({"fps": -3, "frames": [{"blendshapes": {"a": 1}}]}, ["frame rate"]),
    ({"meta": 1}, ["not a weight layout"]),
])
def test_bad_documents(doc, words):
    with pytest.raises(InputError) as err:
        parse(doc)
    assert "f.json" in str(err.value) and all(w in str(err.value) for w in words), str(err.value)


def test_sniff():
    assert framesjson.sniff(b'[{"time": 0, "blendshapes": {}}]')
    assert framesjson.sniff(b'{"0.0": {"jawOpen": 0.1}}')
    assert not framesjson.sniff(b'{"asset": {"version": "2.0"}}')
    assert not framesjson.sniff(b"time,jawOpen\n")
