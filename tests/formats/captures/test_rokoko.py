"""Rokoko Studio face JSON: Live JSON v3 packet streams and lists, v2 packets, weights 0-100 -> 0..1, bad input."""

import importlib
import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import rokoko
from converter.formats.captures.arkit import NAMES
from tests.formats.captures.layout_samples import others, read

FIXTURE = "rokoko_live_v3.jsonl"


def packets() -> list[dict]:
    return [json.loads(line) for line in read(FIXTURE).decode().splitlines()]


def test_v3_stream():
    data = read(FIXTURE)
    assert rokoko.LAYOUT.sniff(data)
    track = rokoko.LAYOUT.parse(data, FIXTURE)
    assert track.source == "rokoko-json" and track.n_frames == 5 and track.fps == 60.0
    assert track.names == list(NAMES)  # the face's keys in file order, faceId dropped
    np.testing.assert_allclose(track.times, np.arange(5) / 60, atol=1e-6)
    assert track.duration == pytest.approx(5 / 60, abs=1e-6)
    # 0..100 in the file, 0..1 in the track; the face is Actor 1's (Actor 2 has none)
    np.testing.assert_allclose(track.values[:, NAMES.index("jawOpen")], [0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(track.values[:, NAMES.index("eyeBlinkLeft")], [0, 0, 1, 0, 0])
    np.testing.assert_allclose(track.values[:, NAMES.index("mouthSmileRight")], 0.125)
    assert track.head is None and track.eye_left is None


def test_packet_list_and_single_packet():
    stream = rokoko.parse(read(FIXTURE), FIXTURE)
    listed = rokoko.parse(json.dumps(packets()).encode(), "list.json")
    np.testing.assert_array_equal(listed.values, stream.values)
    np.testing.assert_array_equal(listed.times, stream.times)
    one = rokoko.parse(json.dumps(packets()[3]).encode(), "one.json")
    assert one.n_frames == 1 and one.fps == 60.0 and one.values[0, NAMES.index("jawOpen")] == pytest.approx(0.75)


def test_v2_faces_with_millisecond_stamps():
    doc = [{"version": 2, "timestamp": 1000 + 40 * k, "props": [], "trackers": [], "actors": [],
            "faces": [{"faceId": "iPhone", "profileName": "me", "jawOpen": 10 * k, "eyeBlinkRight": 50}]}
           for k in range(4)]
    data = json.dumps(doc).encode()
    assert rokoko.sniff(data)
    track = rokoko.parse(data, "v2.json")
    assert track.names == ["jawOpen", "eyeBlinkRight"]
    np.testing.assert_allclose(track.times, [0, 0.04, 0.08, 0.12])
    assert track.fps == pytest.approx(25.0)  # no fps field: the stamps' step
    np.testing.assert_allclose(track.values[:, 0], [0, 0.1, 0.2, 0.3], atol=1e-7)
    np.testing.assert_allclose(track.values[:, 1], 0.5)


def test_repeated_stamps_fall_back_to_the_rate():
    ps = packets()
    for p in ps:
        p["scene"]["timestamp"] = 7.0
    track = rokoko.parse(json.dumps(ps).encode(), "same.json")
    np.testing.assert_allclose(track.times, np.arange(5) / 60)


def test_sniff_claims_only_rokoko():
    assert not any(rokoko.sniff(data) for data in others("rokoko-json").values())


def test_empty():
    with pytest.raises(InputError, match="empty"):
        rokoko.parse(b"  \n", "e.json")


def test_truncated():
    data = read(FIXTURE)
    with pytest.raises(InputError, match="not valid JSON.*truncated"):
        rokoko.parse(data[: len(data) - 40], "cut.jsonl")


def test_nan_weight():
    ps = packets()
    ps[2]["scene"]["actors"][1]["face"]["jawOpen"] = float("nan")
    with pytest.raises(InputError, match=r"packet 2, weight 'jawOpen' is 'nan', not a finite number"):
        rokoko.parse(json.dumps(ps).encode(), "nan.json")


def test_missing_weight_and_missing_face():
    ps = packets()
    del ps[3]["scene"]["actors"][1]["face"]["tongueOut"]
    with pytest.raises(InputError, match=r"packet 3, face 'face-1' has no 'tongueOut' weight"):
        rokoko.parse(json.dumps(ps).encode(), "cols.json")
    ps = packets()
    ps[1]["scene"]["actors"][1]["face"]["faceId"] = "face-2"
    with pytest.raises(InputError, match=r"packet 1 has no face 'face-1'"):
        rokoko.parse(json.dumps(ps).encode(), "mixed.json")


def test_no_face_and_not_packets():
    ps = packets()
    ps[0]["scene"]["actors"][1]["meta"]["hasFace"] = False
    with pytest.raises(InputError, match="the first packet has no face"):
        rokoko.parse(json.dumps(ps).encode(), "noface.json")
    with pytest.raises(InputError, match="neither scene.actors"):
        rokoko.parse(b'{"faceId": 1, "faces": 3}', "odd.json")
    with pytest.raises(InputError, match="not a JSON object"):
        rokoko.parse(b"[1, 2]", "nums.json")


def test_registered():
    registry = importlib.import_module("converter.formats.captures")
    layouts = getattr(registry, "LAYOUTS", ())
    assert rokoko.LAYOUT in (list(layouts.values()) if isinstance(layouts, dict) else list(layouts))
    assert registry.detect(read(FIXTURE)) == rokoko.LAYOUT  # no layout before it in the registry claims the file
