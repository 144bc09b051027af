"""A capture drives a face for as long as the take lasts: the rows' rate, not a timecode's base, sets the frames.

The bug this guards: a real 2 min 14 s Live Link Face take (4,030 rows, 60 fps timecodes stepping two frames a
row: a 30 fps recording) was played one row a frame at 60 fps and lasted 67 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from converter import blendshapes
from converter.animation import Part
from converter.formats import captures
from converter.formats.captures.base import WeightTrack
from converter.formats.morphs import MorphFace
from tests.formats.captures import layout_samples
from tests.formats.captures.test_registry import OWNERS

NAMES = ["JawOpen", "EyeBlinkLeft", "MouthSmileLeft"]


def face_for(names: list[str]) -> MorphFace:
    """A two-triangle face with one morph target per name (its own deltas), so any capture drives it."""
    base = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    rng = np.random.default_rng(len(names))
    deltas = rng.normal(size=(len(names), 4, 3)).astype(np.float32)
    return MorphFace(base, deltas, list(names), np.array([[0, 1, 2], [1, 3, 2]], np.int32), np.zeros(2, np.int32),
                     (Part("skin", (0.8, 0.6, 0.5)),))


def llf_take(rows: int, step: int, start=(13, 13, 4, 31), fraction: str = "652", drop=()) -> tuple[bytes, np.ndarray]:
    """A Live Link Face CSV of `rows` rows whose 60 fps timecodes advance `step` frames a row; the weights."""
    k = np.arange(rows)
    w = 0.5 + 0.5 * np.sin(k[:, None] / 17.0 + np.arange(len(NAMES))[None])
    h, m, s, f = start
    first = ((h * 60 + m) * 60 + s) * 60 + f
    lines = ["Timecode,BlendShapeCount," + ",".join(NAMES)]
    for i in k:
        if i in drop:
            continue
        frame = first + step * i
        tc = f"{frame // 216000:02d}:{frame // 3600 % 60:02d}:{frame // 60 % 60:02d}:{frame % 60:02d}.{fraction}"
        lines.append(f"{tc},{len(NAMES)}," + ",".join(f"{x:.6f}" for x in w[i]))
    return ("\n".join(lines) + "\n").encode(), w


def animation_seconds(anim) -> float:
    return anim.n_frames / anim.fps


def test_a_30fps_take_with_60fps_timecodes_lasts_as_long_as_recorded():
    data, w = llf_take(4030, 2)
    track = captures.parse_capture(data, "MySlate_7.csv")
    assert track.fps == 30.0 and track.is_regular()
    take = 4030 / 30  # 2 min 14.3 s
    assert track.duration == pytest.approx(take, abs=1e-6)
    assert track.start_timecode == "13:13:04:31.652"
    np.testing.assert_allclose(track.times[:3], [0, 2 / 60, 4 / 60])
    anim = blendshapes.drive(face_for(NAMES), track)
    assert anim.fps == 30.0 and anim.n_frames == 4030
    assert animation_seconds(anim) == pytest.approx(take, abs=1 / anim.fps)
    # frame k is row k: the first target's delta, scaled by the row's weight
    face = face_for(NAMES)
    k = 2500
    expected = face.base + np.tensordot(w[k].astype(np.float32), face.deltas, axes=1)
    np.testing.assert_allclose(anim.frames[k], expected, atol=1e-5)


def test_a_take_with_dropped_rows_is_resampled_onto_its_rate():
    dropped = set(range(100, 160)) | {400, 401, 402, 777}
    data, w = llf_take(1000, 2, drop=dropped)
    track = captures.parse_capture(data, "gappy.csv")
    assert track.n_frames == 1000 - len(dropped)
    assert track.fps == 30.0 and not track.is_regular(tol=0.5)
    take = 1000 / 30  # the last row is still at 999 * 2 / 60 s
    assert track.duration == pytest.approx(take, abs=1e-6)
    anim = blendshapes.drive(face_for(NAMES), track)
    assert anim.fps == 30.0
    assert animation_seconds(anim) == pytest.approx(take, abs=1 / anim.fps)
    assert anim.n_frames == 1000  # every 1/30 s of the take, the dropped ones interpolated
    face = face_for(NAMES)
    for k in (50, 500, 999):  # rows kept: frame k is row k again
        expected = face.base + np.tensordot(w[k].astype(np.float32), face.deltas, axes=1)
        np.testing.assert_allclose(anim.frames[k], expected, atol=1e-4)


def test_a_drifting_clock_within_half_a_frame_keeps_one_row_a_frame():
    # times 1.0006 frames apart (the shared MySlate_3 take's 59.96 Hz camera): 60 fps, rows kept as they are
    times = np.arange(300) * 1.0006 / 60
    track = WeightTrack(["JawOpen"], times, np.linspace(0, 1, 300, dtype=np.float32)[:, None], 60.0)
    anim = blendshapes.drive(face_for(["JawOpen"]), track)
    assert anim.n_frames == 300 and anim.fps == 60.0


def test_an_asked_rate_resamples_the_take_and_keeps_its_length():
    data, _ = llf_take(600, 2)
    track = captures.parse_capture(data, "take.csv")
    anim = blendshapes.drive(face_for(NAMES), track, fps=24)
    assert anim.fps == 24 and animation_seconds(anim) == pytest.approx(600 / 30, abs=1 / 24)


@pytest.mark.parametrize("fixture", sorted(OWNERS))
def test_every_layout_drives_for_the_takes_duration(fixture):
    track = captures.parse_capture(layout_samples.read(fixture), fixture)
    anim = blendshapes.drive(face_for(track.names), track)
    assert anim.fps == pytest.approx(track.fps)
    assert animation_seconds(anim) == pytest.approx(track.duration, abs=1 / anim.fps)


def test_facecap_with_dropped_frames_lasts_as_recorded():
    lines = layout_samples.read("facecap_sample.txt").decode().splitlines()
    kept = [ln for i, ln in enumerate(lines) if i not in (10, 11, 12, 25)]  # line 0 is bs; k lines 1..40
    track = captures.parse_capture(("\n".join(kept) + "\n").encode(), "fc.txt")
    assert track.fps == 30.0 and track.n_frames == 36
    anim = blendshapes.drive(face_for(track.names), track)
    assert anim.n_frames == 40 and animation_seconds(anim) == pytest.approx(40 / 30, abs=1 / 30)
