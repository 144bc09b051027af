"""Weight capture readers: the real Live Link Face CSV, the JSON layouts tools write, and bad input."""

import csv
import json

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.weights import is_capture, parse_weights, read_weights

LLF = "real/livelinkface_MySlate_3.csv"


def test_live_link_face_csv(shared_data):
    path = shared_data / LLF
    track = read_weights(path)
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    assert track.n_frames == len(body) == 328
    assert len(track.names) == 52 and track.names[0] == "EyeBlinkLeft" and track.names[-1] == "TongueOut"
    assert track.fps == 60.0 and track.start_timecode == body[0][0]
    jaw = header.index("JawOpen")
    np.testing.assert_allclose(track.values[:, track.names.index("JawOpen")], [float(r[jaw]) for r in body], atol=1e-7)
    # times follow the timecode: 00:32:09:07.867 -> 00:32:09:08.868 is (1 + 0.001) / 60 s
    assert track.times[1] == pytest.approx(1.001 / 60, abs=1e-9)
    assert track.times[-1] == pytest.approx(np.sum(np.diff(track.times)))
    # angles: -1..1 = -180..180 degrees in the file (Epic's ToBlendShapeMap), radians (x pi) in the track
    eye = header.index("LeftEyeYaw")
    np.testing.assert_allclose(track.eye_left[:, 0], [float(r[eye]) * np.pi for r in body], rtol=1e-6)
    assert track.head is not None and not track.head.any()


def test_timecode_rate_from_the_frame_field():
    head = "Timecode,BlendShapeCount,JawOpen\n"
    rows = "".join(f"00:00:0{s}:{f:02d}.000,1,0.{f:02d}\n" for s in (1, 2) for f in range(0, 30, 2))
    track = parse_weights((head + rows).encode(), "t.csv")
    # 30 fps timecodes, a row every second frame: the take is 15 fps, its times as written
    assert track.fps == 15.0 and track.times[1] == pytest.approx(2 / 30)


def test_audio2face_json():
    doc = {"exportFps": 30, "trackPath": "/World/audio", "numPoses": 2, "numFrames": 3,
           "facsNames": ["jawOpen", "eyeBlinkLeft"], "weightMat": [[0, 1], [0.5, 0], [1, 0.25]]}
    data = json.dumps(doc).encode()
    track = parse_weights(data, "a2f.json")
    assert track.names == ["jawOpen", "eyeBlinkLeft"] and track.fps == 30.0
    np.testing.assert_allclose(track.times, [0, 1 / 30, 2 / 30])
    np.testing.assert_allclose(track.values[:, 0], [0, 0.5, 1])
    assert is_capture(data) == "an Audio2Face blendshape weight export"


def test_frame_list_layouts():
    dicts = [{"time": 0.0, "blendshapes": {"jawOpen": 0.1, "eyeBlink_L": 0.0}},
             {"time": 0.05, "blendshapes": {"jawOpen": 0.3, "eyeBlink_L": 1.0}}]
    t = parse_weights(json.dumps(dicts).encode(), "f.json")
    assert t.names == ["jawOpen", "eyeBlink_L"] and t.fps == pytest.approx(20.0)
    mediapipe = [{"timestamp": 1000 + 33 * k, "blendshapes": [{"categoryName": "jawOpen", "score": 0.1 * k}]}
                 for k in range(4)]
    t = parse_weights(json.dumps(mediapipe).encode(), "mp.json")
    assert t.times[1] == pytest.approx(0.033) and t.values[3, 0] == pytest.approx(0.3)
    keyed = {"0.0": {"jawOpen": 0.2}, "0.5": {"jawOpen": 0.4}}
    t = parse_weights(json.dumps(keyed).encode(), "k.json")
    assert t.times[-1] == pytest.approx(0.5) and t.values[:, 0].tolist() == pytest.approx([0.2, 0.4])
    wrapped = {"fps": 25, "frames": [{"blendshapes": {"jawOpen": 0.5}}] * 3}
    t = parse_weights(json.dumps(wrapped).encode(), "w.json")
    assert t.fps == 25.0 and t.n_frames == 3


@pytest.mark.parametrize("text,words", [
    ("Timecode,JawOpen\n00:00:00:00.000,0.1\n", ["x.csv", "BlendShapeCount"]),
    ("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,abc\n", ["x.csv", "row 2", "JawOpen", "not a number"]),
    ("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,nan\n", ["x.csv", "JawOpen", "NaN"]),
    ("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1\n", ["x.csv", "row 2", "cells"]),
    ("Timecode,BlendShapeCount,JawOpen\nyesterday,1,0.2\n", ["x.csv", "timecode"]),
    ("Timecode,BlendShapeCount,JawOpen\n", ["x.csv", "no frames"]),
    ('{"asset": {"version": "2.0"}}', ["x.csv", "not a weight layout"]),
    ('{"facsNames": ["a"], "weightMat": [[0.1], ["x"]]}', ["x.csv", "weightMat", "not numbers"]),
    ('{"facsNames": ["a"], "weightMat": [[0.1, 0.2]]}', ["x.csv", "weightMat", "expected 1"]),
    ('[{"time": 0, "blendshapes": {"jawOpen": null}}]', ["x.csv", "jawOpen", "not a finite number"]),
    ('[{"time": 0}]', ["x.csv", "no blendshapes"]),
    ("{not json", ["x.csv", "not valid JSON"]),
    ("", ["x.csv", "empty"]),
])
def test_bad_captures_name_the_file_and_the_problem(text, words):
    with pytest.raises(InputError) as err:
        parse_weights(text.encode(), "x.csv")
    msg = str(err.value)
    assert all(w in msg for w in words), msg
    assert msg.count(". ") == 0 and msg.endswith(".")  # one sentence


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        read_weights(tmp_path / "nope.csv")
