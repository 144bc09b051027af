"""Real faces (../shared/data): the ICT FaceKit head and the Ready Player Me avatar driven by the real Live Link
Face take, with a head sweep within +-20 degrees added, in Chromium against the 3D prerender."""

from __future__ import annotations

import numpy as np
import pytest
from test_player import IOU_MIN, JS_PX, canvas_alpha, iou, js_positions, open_puppet, quantised, reference_alpha

from converter.formats.captures.base import WeightTrack
from converter.formats.morphs import load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions, Report
from converter.puppet import from_track, pose, puppet_of, resolve
from converter.puppet.take import frame_pose, frame_times
from converter.writers import puppet as writer

LLF = "real/livelinkface_MySlate_3.csv"
FACES = {"ict": "ict_facekit", "rpm": "real/rpm_template_xr.glb"}


def take_with_head_sweep(path) -> WeightTrack:
    """The real take (its head angles are all 0) with yaw +-20, pitch +-15 degrees and roll +-0.2 rad added."""
    track = read_weights(path)
    ph = np.linspace(0, 1, track.n_frames)
    head = np.stack([np.radians(20) * np.sin(2 * np.pi * ph), np.radians(-15) * np.sin(4 * np.pi * ph + 1),
                     0.2 * np.sin(2 * np.pi * ph + 2)], axis=1).astype(np.float32)
    return WeightTrack(track.names, track.times, track.values, track.fps, head=head, eye_left=track.eye_left,
                       eye_right=track.eye_right)


@pytest.mark.shared
@pytest.mark.browser
@pytest.mark.parametrize("which", sorted(FACES))
def test_real_face_and_take_match_the_3d_render(browser, shared_data, tmp_path, which, artifacts):
    face = load_morph_face(shared_data / FACES[which])
    puppet = puppet_of(face, ConversionOptions(size=256))
    track = take_with_head_sweep(shared_data / LLF)
    take = from_track(track)
    frames = list(range(0, take.n_frames, take.n_frames // 8))[:8]
    refs = reference_alpha(face, puppet, quantised(track, take), frames)
    mapping = resolve(puppet, take.names)
    assert mapping.any(axis=1).sum() >= 25  # ICT names 25 of the 52 ARKit weights, the avatar all 52
    times = frame_times(take)
    page = open_puppet(browser, tmp_path, writer.write(puppet.with_take(take), ConversionOptions(), Report()))
    scores = []
    try:
        for k in frames:
            page.evaluate("(t) => puppet.seek(t)", float(times[k]) + 1e-9)
            w, head, eyes = frame_pose(take, k)
            want, _ = pose(puppet, w @ mapping, head=head, eyes=eyes)
            got, _ = js_positions(page)
            assert np.abs(got - want).max() <= JS_PX, f"frame {k}"
            scores.append(iou(canvas_alpha(page) > 127, refs[k] > 127))
    finally:
        page.close()
    (artifacts / f"puppet_{which}_iou.txt").write_text(" ".join(f"{s:.4f}" for s in scores))
    assert min(scores) >= IOU_MIN, scores
