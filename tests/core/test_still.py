"""Stills (--frame K): only frame K decides which triangles are drawn."""

import numpy as np

from converter import idpass
from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation
from converter.options import ConversionOptions
from converter.verify import evaluate


def test_still_renders_occlusion_for_its_own_frame_only(monkeypatch):
    # A square behind a larger one that slides away: hidden at frame 0, seen at frame 2. The animation keeps
    # it; the still of frame 0 needs only frame 0's id render, and drops it.
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)
    frames = np.stack([np.concatenate([quad + [3 * k, 0, 0], quad * [0.5, 0.5, 1] + [0, 0, -0.5]])
                       for k in range(3)]).astype(np.float32)
    anim = FaceAnimation(frames, faces, np.zeros(4, np.int32), (Part("skin", (0.8, 0.6, 0.5)),), 10.0, "slide")
    rendered = []
    real = idpass.ever_seen

    def spy(fr, *a, **k):
        rendered.append(len(fr))
        return real(fr, *a, **k)

    monkeypatch.setattr(idpass, "ever_seen", spy)
    still = convert_animation(anim, ConversionOptions(size=64, frame=0)).data
    movie = convert_animation(anim, ConversionOptions(size=64)).data
    assert rendered == [1, 3]
    assert b'id="f2"' not in still and b'id="f3"' not in still and b'id="f0"' in still
    assert {2, 3} <= set(evaluate(movie).triangles.tolist())  # drawn (merged paths carry their first's id)
