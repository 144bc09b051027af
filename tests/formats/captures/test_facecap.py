"""Face Cap text export: bs names, k frames in milliseconds, head and eye angles from degrees."""

from __future__ import annotations

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import facecap
from tests.formats.captures.layout_samples import read

FIXTURE = "facecap_sample.txt"


def table() -> tuple[list[str], np.ndarray]:
    lines = read(FIXTURE).decode().splitlines()
    names = lines[0].split(",")[1:]
    return names, np.array([[float(c) for c in ln.split(",")[1:]] for ln in lines[1:]])


def test_the_fixture_column_by_column():
    names, k = table()
    track = facecap.parse(read(FIXTURE), FIXTURE)
    assert track.names == names and track.n_frames == 40 and track.fps == 30.0
    np.testing.assert_allclose(track.times, (k[:, 0] - k[0, 0]) / 1000)
    np.testing.assert_allclose(track.values, k[:, 11:], atol=1e-6)
    # head rot x, y, z = pitch, yaw, roll in degrees, signs opposite to Live Link Face's
    np.testing.assert_allclose(track.head[:, 0], -np.radians(k[:, 5]), atol=1e-6)
    np.testing.assert_allclose(track.head[:, 1], -np.radians(k[:, 4]), atol=1e-6)
    np.testing.assert_allclose(track.head[:, 2], -np.radians(k[:, 6]), atol=1e-6)
    np.testing.assert_allclose(track.eye_left[:, :2], np.radians(k[:, [8, 7]]), atol=1e-6)
    np.testing.assert_allclose(track.eye_right[:, :2], np.radians(k[:, [10, 9]]), atol=1e-6)


def test_other_lines_are_skipped():
    data = b"info,FaceCap,1.0\n" + read(FIXTURE) + b"\nsomething,else\n"
    assert facecap.parse(data, "f.txt").n_frames == 40


@pytest.mark.parametrize("edit,words", [
    (lambda t: t.replace("k,0,", "k,0,1,", 1), ["line 2", "values after k"]),
    (lambda t: t.split("\n", 1)[1], ["no bs line"]),
    (lambda t: t.split("\n", 1)[0], ["no k frame lines"]),
    (lambda t: t.replace("k,33,", "k,0,", 1), ["line 3", "not after"]),
    (lambda t: t.replace("k,0,", "k,nan,", 1), ["line 2", "NaN"]),
])
def test_bad_exports_name_the_line(edit, words):
    with pytest.raises(InputError) as err:
        facecap.parse(edit(read(FIXTURE).decode()).encode(), "f.txt")
    assert str(err.value).startswith("f.txt") and all(w in str(err.value) for w in words), str(err.value)


def test_sniff():
    assert facecap.sniff(read(FIXTURE))
    assert not facecap.sniff(b"bs,jawOpen\n")  # names without frames
    assert not facecap.sniff(read("ifacialmocap_frame.txt"))
