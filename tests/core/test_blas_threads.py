"""The converter's many small products run with numpy's BLAS on one thread (its threads spin more than they
compute on them), and the caller's own BLAS threading is restored afterwards."""

import numpy as np
from threadpoolctl import threadpool_info

from converter.animation import FaceAnimation, Part
from converter.convert import convert_animation
from converter.options import ConversionOptions
from converter.outputs import output_kind


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_conversion_runs_blas_on_one_thread_and_restores_it(monkeypatch):
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    frames = np.stack([quad + [0.1 * k, 0, 0] for k in range(4)]).astype(np.float32)
    anim = FaceAnimation(frames, np.array([[0, 1, 2], [0, 2, 3]], np.int32), np.zeros(2, np.int32),
                         (Part("skin", (0.8, 0.6, 0.5)),), 10.0, "quad")
    kind = output_kind("svg")
    real = kind.shading_writers["flat"]
    seen = []

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setitem(kind.shading_writers, "flat", spy)
    before = _blas_threads()
    assert before, "numpy links no BLAS that threadpoolctl sees"
    out = convert_animation(anim, ConversionOptions(size=64)).data
    assert out.startswith(b"<svg") or b"<svg" in out[:200]
    assert seen == [[1] * len(before)]
    assert _blas_threads() == before
