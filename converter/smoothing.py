"""Optional temporal smoothing (--smooth SIGMA): capture jitter out of the vertex tracks, at a reported cost.

Captured motion jitters by a fraction of a pixel every frame, and an error-bounded encoder must follow every
wiggle larger than its tolerance. Smoothing each vertex track over time with a Gaussian of SIGMA frames
(scipy.ndimage.gaussian_filter1d; track ends are extended by their end value) removes that jitter, and with
it also some real detail (a fast blink's extreme, a plosive's jaw snap). It is off by default, and it is
never silent: the conversion reports the largest and mean distance, in output pixels at the output camera,
between every smoothed vertex and the unsmoothed input (``deviation_px``). The file's stated tolerance is
measured against the smoothed animation (the verifier applies the same stage), so the total deviation from
the unsmoothed input is at most tolerance + the reported smoothing deviation.
"""

from __future__ import annotations

import numpy as np

from converter.animation import FaceAnimation
from converter.camera import Camera
from converter.errors import InputError
from converter.extract import fit_camera

MAX_SIGMA = 30.0  # frames; beyond this the animation is a blur of itself


def smooth(anim: FaceAnimation, sigma: float) -> FaceAnimation:
    """The animation with each vertex track low-passed over time by a Gaussian of sigma frames (0 = as is)."""
    if not (np.isfinite(sigma) and 0 <= sigma <= MAX_SIGMA):
        raise InputError(f"smooth must be between 0 and {MAX_SIGMA:g} frames, got {sigma}.")
    if sigma == 0 or anim.n_frames < 2:
        return anim
    from scipy.ndimage import gaussian_filter1d  # noqa: PLC0415 - slow to import; only --smooth needs it

    frames = gaussian_filter1d(anim.frames.astype(np.float64), sigma, axis=0, mode="nearest")
    return anim.with_frames(frames.astype(np.float32))


def deviation_px(before: np.ndarray, after: np.ndarray, camera: Camera) -> tuple[float, float]:
    """Max and mean distance in output px between two (T, V, 3) vertex sets projected by camera."""
    a = camera.project(before)[0]
    b = camera.project(after)[0]
    d = np.linalg.norm(a.astype(np.float64) - b, axis=-1)
    return float(d.max()), float(d.mean())


def apply(anim: FaceAnimation, options, report) -> FaceAnimation:
    """The --smooth stage of convert.prepare: smooth, and report the deviation at the output camera."""
    if not options.smooth:
        return anim
    out = smooth(anim, options.smooth)
    camera = fit_camera(out, options.size, options.yaw, options.pitch, options.fov, options.ortho, options.frame_on)
    report.figures["smooth_max_px"], report.figures["smooth_mean_px"] = deviation_px(anim.frames, out.frames, camera)
    return out
