"""Live Link Face CSV: the real take's values, its timing from the rows' spacing, its angles at 180 degrees a unit."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats.captures import livelinkface
from tests.formats.captures.layout_samples import read

CUT = "livelinkface_myslate3_cut.csv"


def rows(data: bytes) -> tuple[list[str], list[list[str]]]:
    table = list(csv.reader(io.StringIO(data.decode())))
    return table[0], table[1:]


def test_the_cut_of_the_real_take_reads_as_written():
    data = read(CUT)
    header, body = rows(data)
    track = livelinkface.parse(data, CUT)
    assert track.n_frames == len(body) == 24 and track.fps == 60.0
    assert track.names == header[2:54] and track.names[-1] == "TongueOut"
    jaw = header.index("JawOpen")
    np.testing.assert_allclose(track.values[:, track.names.index("JawOpen")], [float(r[jaw]) for r in body], atol=1e-7)
    # times as recorded: 00:32:09:07.867 -> :08.868 is (1 + 0.001) / 60 s
    assert track.times[1] == pytest.approx(1.001 / 60, abs=1e-9)
    # angles: -1..1 = -180..180 degrees (Epic's ToBlendShapeMap divides degrees by 180)
    for side, angles in (("Left", track.eye_left), ("Right", track.eye_right)):
        for j, axis in enumerate(("Yaw", "Pitch", "Roll")):
            col = header.index(f"{side}Eye{axis}")
            np.testing.assert_allclose(angles[:, j], [np.radians(float(r[col]) * 180) for r in body], rtol=1e-6)
    assert track.head is not None and not track.head.any()


def test_vergence_of_the_real_take_is_a_phone_held_in_front_of_the_face():
    # the units' evidence: the eyes' yaw difference is 12-13 degrees, eyes fixating ~28 cm away (a 63 mm IPD)
    track = livelinkface.parse(read(CUT), CUT)
    vergence = np.abs(np.median(track.eye_left[:, 0] - track.eye_right[:, 0]))
    distance = 0.0315 / np.tan(vergence / 2)
    assert 0.2 < distance < 0.4


@pytest.mark.shared
def test_the_whole_real_take(shared_data):
    track = livelinkface.parse((shared_data / "real/livelinkface_MySlate_3.csv").read_bytes(), "MySlate_3.csv")
    assert track.n_frames == 328 and track.fps == 60.0 and track.is_regular(tol=0.5)
    assert track.duration == pytest.approx(327.199 / 60 + 1 / 60, abs=1e-6)


def test_a_shorter_take_than_a_second_and_a_single_row():
    head = "Timecode,BlendShapeCount,JawOpen\n"
    track = livelinkface.parse((head + "00:00:01:10.000,1,0.5\n00:00:01:12.000,1,0.25\n").encode(), "t.csv")
    assert track.fps == 30.0 and track.times[1] == pytest.approx(2 / 60)
    track = livelinkface.parse((head + "00:00:01:10.000,1,0.5\n").encode(), "t.csv")
    assert track.n_frames == 1 and track.fps == 60.0


def test_a_timecode_going_back_is_refused():
    data = b"Timecode,BlendShapeCount,JawOpen\n00:00:01:10.000,1,0.5\n00:00:01:09.000,1,0.2\n"
    with pytest.raises(InputError, match=r"^t\.csv row 3: the timecode does not increase"):
        livelinkface.parse(data, "t.csv")


def test_sniff():
    assert livelinkface.sniff(read(CUT))
    assert livelinkface.sniff(b"\xef\xbb\xbfTimecode,BlendShapeCount,JawOpen\n")
    assert not livelinkface.sniff(b"time,jawOpen\n0,0.1\n")
    assert not livelinkface.sniff(read("facecap_sample.txt"))
