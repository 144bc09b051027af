"""iFacialMocap frames as text: weights /100, head and eyes in degrees, unknown items skipped."""

from __future__ import annotations

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import ifacialmocap
from tests.formats.captures.layout_samples import read


def items(line: str) -> tuple[dict[str, float], dict[str, list[float]]]:
    """The frame's name-value items and #-transforms, split by hand."""
    weights, transforms = {}, {}
    for item in line.strip().split("|"):
        item = item.lstrip("=")
        if "#" in item:
            key, vals = item.split("#")
            transforms[key] = [float(v) for v in vals.split(",")]
        elif "-" in item and item.split("-")[0].isidentifier():
            weights[item.split("-")[0]] = float(item.split("-")[1])
    return weights, transforms


@pytest.mark.parametrize("fixture", ["ifacialmocap_frame.txt", "ifacialmocap_frame_extra_key.txt"])
def test_the_real_frames(fixture):
    weights, transforms = items(read(fixture).decode())
    track = ifacialmocap.parse(read(fixture), fixture)
    assert track.n_frames == 1 and len(track.names) == 52 and "hapihapi" not in track.names
    for n in track.names:
        assert track.values[0, track.names.index(n)] == pytest.approx(weights[n] / 100)
    rx, ry, rz = transforms["head"][:3]
    np.testing.assert_allclose(track.head[0], -np.radians([ry, rx, rz]), atol=1e-6)
    x, y, z = transforms["leftEye"]
    np.testing.assert_allclose(track.eye_left[0], np.radians([y, x, z]), atol=1e-6)
    x, y, z = transforms["rightEye"]
    np.testing.assert_allclose(track.eye_right[0], np.radians([y, x, z]), atol=1e-6)


def test_a_recording_is_one_frame_a_line_at_60fps():
    data = read("ifacialmocap_frame.txt").strip() + b"\n" + read("ifacialmocap_frame_extra_key.txt").strip() + b"\n"
    track = ifacialmocap.parse(data, "rec.txt")
    assert track.n_frames == 2 and track.fps == 60.0 and track.times[1] == pytest.approx(1 / 60)


@pytest.mark.parametrize("data,words", [
    (b"=head#1,2,3,4,5,6|rightEye#1,2,3|leftEye#1,2,3|", ["line 1", "no blendshape weights"]),
    (b"jawOpen-10|=head#1,2|", ["line 1", "head has 2 values"]),
    (b"jawOpen-10|=head#1,x,3,4,5,6|", ["line 1", "not a number"]),
])
def test_bad_frames(data, words):
    with pytest.raises(InputError) as err:
        ifacialmocap.parse(data, "i.txt")
    assert str(err.value).startswith("i.txt") and all(w in str(err.value) for w in words), str(err.value)


@pytest.mark.shared
def test_the_real_files_are_the_fixtures(shared_data):
    for name in ("ifacialmocap_frame.txt", "ifacialmocap_frame_extra_key.txt"):
        assert (shared_data / "real" / name).read_bytes() == read(name)
