"""Animation sampling (LINEAR with slerp, STEP, CUBICSPLINE), TRS matrices and the rate keys were baked at."""

from __future__ import annotations

import numpy as np


def sample(times: np.ndarray, values: np.ndarray, interp: str, t: np.ndarray, rotation: bool = False) -> np.ndarray:
    """A glTF sampler evaluated at times t, clamped outside its keys: (len(t), C)."""
    n = len(times)
    if interp == "CUBICSPLINE":
        v = values.reshape(n, 3, -1)
        a, p, b = v[:, 0], v[:, 1], v[:, 2]
    else:
        p = values
    if rotation:
        p = p / np.linalg.norm(p, axis=1, keepdims=True)
    if n == 1:
        return np.repeat(p[:1], len(t), axis=0)
    # Keys are float32: a key at 0.3 s is stored as 0.30000001, so snap sample times within float32 error.
    after = np.searchsorted(times, t + np.maximum(1e-6, np.abs(t) * 1e-6), side="right") - 1
    if interp == "STEP":
        return p[np.clip(after, 0, n - 1)]
    k = np.clip(after, 0, n - 2)
    dt = times[k + 1] - times[k]
    u = np.clip(np.where(dt > 0, (t - times[k]) / np.where(dt > 0, dt, 1.0), 1.0), 0.0, 1.0)[:, None]
    if interp == "LINEAR":
        if rotation:
            return slerp(p[k], p[k + 1], u)
        return p[k] * (1 - u) + p[k + 1] * u
    u2, u3, d = u * u, u * u * u, dt[:, None]
    out = ((2 * u3 - 3 * u2 + 1) * p[k] + (u3 - 2 * u2 + u) * d * b[k]
           + (-2 * u3 + 3 * u2) * p[k + 1] + (u3 - u2) * d * a[k + 1])
    if rotation:
        out = out / np.linalg.norm(out, axis=1, keepdims=True)
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shorter arc, rows (x, y, z, w)."""
    d = np.sum(q0 * q1, axis=1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    near = s < 1e-6
    safe = np.where(near, 1.0, s)
    w0 = np.where(near, 1 - u, np.sin((1 - u) * theta) / safe)
    w1 = np.where(near, u, np.sin(u * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def trs_matrices(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(N, 4, 4) matrices T * R * S from broadcastable (N|1, 3) translations, (x, y, z, w) quaternions, scales."""
    n = max(len(t), len(q), len(s))
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = (np.broadcast_to(q[:, i], (n,)) for i in range(4))
    r = np.empty((n, 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = r * np.broadcast_to(s, (n, 3))[:, None, :]
    m[:, :3, 3] = np.broadcast_to(t, (n, 3))
    m[:, 3, 3] = 1.0
    return m


def keyframe_rate(all_times: list[np.ndarray]) -> float | None:
    """The frame rate keys were baked at when evident (every gap a whole number of one step, 12..240 fps)."""
    if not all_times:
        return None
    times = np.unique(np.concatenate(all_times))
    if len(times) < 3:
        return None
    gaps = np.diff(times)
    step = gaps.min()
    if step <= 0:
        return None
    ratio = gaps / step
    if np.abs(ratio - np.round(ratio)).max() > 1e-3:
        return None
    rate = 1.0 / step
    if not 12.0 <= rate <= 240.0:
        return None
    whole = round(rate)
    return float(whole) if abs(rate - whole) < 1e-3 * rate else round(rate, 3)
