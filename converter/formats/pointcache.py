"""A rest mesh (OBJ, or any loader's one frame) + a PC2, MDD or .npy point cache to FaceAnimation.

PC2 (3ds Max, Blender, Maya): 'POINTCACHE2\\0', int32 version, int32 points, float32 start frame, float32 sample
rate (scene frames per sample), int32 samples, then float32 xyz; little-endian. PC2 does not store the scene's
frame rate: samples are sampleRate scene frames apart and the scene runs at `fps` (default 30), so with the
usual sampleRate 1 every sample is one output frame.

MDD (LightWave, Blender): big-endian int32 frames, int32 points, float32 times[frames] in seconds, then float32
xyz per frame. Times, when increasing, set the source rate; the cache is resampled (linearly) to `fps`.

.npy (speech-driven face research: VOCASET, FaceFormer, BIWI): a float array (T, V, 3) or (T, V*3) of vertex
positions in the template mesh's order, one frame per row; no rate is stored (VOCASET is 60 fps, BIWI 25; give
--fps, default 30).

Axes. Blender writes MDD in its own Z-up world space (recent exporters; Blender 2.5x swapped y and z instead)
while its OBJ exporter writes Y-up by default, so the cache and the OBJ disagree by an axis change. With
axes="auto" (default) we try the candidate axis maps in AXIS_MAPS on the first cache frame and keep the one
that lands closest to the OBJ rest positions (identity wins ties); "none", "zup" or "swapyz" force one.
"""

from __future__ import annotations

import io
import math
import struct

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.obj import parse_obj
from converter.formats.parts import parts_for_groups

DEFAULT_FPS = 30.0
MAX_FRAMES = 100_000
PC2_MAGIC = b"POINTCACHE2\0"
NPY_MAGIC = b"\x93NUMPY"
# Each map takes cache (x, y, z) to OBJ axes.
AXIS_MAPS = {
    "none": lambda p: p,
    "zup": lambda p: np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1),  # Blender Z-up -> OBJ Y-up
    "swapyz": lambda p: np.stack([p[..., 0], p[..., 1], -p[..., 2]], axis=-1),  # Blender 2.5x y/z swap -> Y-up
}


def load_obj_static(obj_bytes: bytes, fps: float | None = None, name: str = "face") -> FaceAnimation:
    """An OBJ mesh on its own: a one-frame animation (a face to clone onto, to drive by FAPs, or a still)."""
    rest, faces, groups_of_face, groups = parse_obj(obj_bytes.decode("utf-8", errors="replace"), f"{name}.obj")
    parts, part_ids = parts_for_groups(groups, groups_of_face)
    return FaceAnimation(rest[None], faces, part_ids, parts, float(fps) if fps else DEFAULT_FPS, name,
                         extras={"static": True})


def load_obj_cache(obj_bytes: bytes, cache_bytes: bytes, fps: float | None = None, name: str = "face",
                   axes: str = "auto") -> FaceAnimation:
    """An OBJ rest mesh animated by a PC2, MDD or .npy point cache, resampled at fps (default: the cache's rate)."""
    rest, faces, groups_of_face, groups = parse_obj(obj_bytes.decode("utf-8", errors="replace"), f"{name}.obj")
    parts, part_ids = parts_for_groups(groups, groups_of_face)
    return animate(FaceAnimation(rest[None], faces, part_ids, parts, DEFAULT_FPS, name), cache_bytes, fps, axes, "OBJ")


def animate(mesh: FaceAnimation, cache_bytes: bytes, fps: float | None = None, axes: str = "auto",
            kind: str = "mesh") -> FaceAnimation:
    """A one-frame rest mesh (from any loader) animated by a PC2, MDD or .npy point cache."""
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}.")
    if axes not in ("auto", *AXIS_MAPS):
        raise InputError(f"unknown axes {axes!r}; use auto, none, zup or swapyz.")
    rest = mesh.frames[0]
    if cache_bytes[:12] == PC2_MAGIC:
        points, times = read_pc2(cache_bytes, fps or DEFAULT_FPS)
    elif cache_bytes[:6] == NPY_MAGIC:
        points, times = read_npy(cache_bytes, len(rest)), np.zeros(0)
    else:
        points, times = read_mdd(cache_bytes)
    if points.shape[1] != len(rest):
        raise InputError(f"the point cache has {points.shape[1]} points but the {kind} has {len(rest)} vertices; "
                         "export both from the same mesh.")
    if not np.isfinite(points).all():
        raise InputError("the point cache has NaN or infinite positions; re-export it.")
    points = AXIS_MAPS[axes if axes != "auto" else detect_axes(points[0], rest)](points)
    source_fps = rate_of(times)
    out_fps = float(fps) if fps else (source_fps or DEFAULT_FPS)
    if source_fps is None:  # no usable times: one sample per output frame
        times = np.arange(len(points)) / out_fps
    frames = resample(points, times, out_fps)
    extras = {k: v for k, v in mesh.extras.items() if k != "static"}
    return mesh.with_frames(frames, fps=out_fps,
                            extras={**extras, "source_fps": source_fps, "cache_frames": int(len(points))})


def read_npy(data: bytes, n_points: int) -> np.ndarray:
    """A NumPy vertex array (T, V, 3), or (T, V*3) as VOCASET/FaceFormer store it, as float32 (T, V, 3).

    Read with allow_pickle=False: an .npy can carry pickled objects, which we never load.
    """
    try:
        arr = np.load(io.BytesIO(data), allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc).lower():
            raise InputError("the .npy holds pickled Python objects, which facesvg does not load; save the vertices "
                             "as a plain float array (np.save(path, vertices.astype('float32'))).") from None
        raise InputError(f"the .npy vertex array is not readable ({str(exc)[:60]}); re-save it.") from None
    except (OSError, EOFError):
        raise InputError("the .npy vertex array is truncated; re-save it.") from None
    if arr.dtype.kind not in "fiu":
        raise InputError(f"the .npy vertex array holds {arr.dtype} values, not numbers; save float vertices.")
    if arr.ndim == 2 and arr.shape[1] == 3 * n_points:
        arr = arr.reshape(len(arr), n_points, 3)
    if arr.ndim != 3 or arr.shape[2] != 3 or len(arr) == 0:
        raise InputError(f"the .npy vertex array has shape {arr.shape}; it must be (frames, {n_points}, 3) or "
                         f"(frames, {3 * n_points}) for this mesh.")
    if len(arr) > MAX_FRAMES:
        raise InputError(f"the .npy vertex array has {len(arr)} frames, more than {MAX_FRAMES}; trim it.")
    return arr.astype(np.float32)


def read_pc2(data: bytes, scene_fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(samples (S, P, 3) float32, sample times in seconds) of a PC2 cache with the scene at scene_fps."""
    if len(data) < 32:
        raise InputError("the PC2 file is truncated: its 32-byte header is incomplete.")
    _, version, n_points, start, rate, n_samples = struct.unpack_from("<12siiffi", data)
    if n_points <= 0 or n_samples <= 0:
        raise InputError(f"the PC2 file has {n_samples} samples of {n_points} points; export at least one frame.")
    if not (math.isfinite(rate) and rate > 0 and math.isfinite(start)):
        raise InputError(f"the PC2 file has an invalid sample rate {rate}; re-export it.")
    need = 32 + n_samples * n_points * 12
    if len(data) < need:
        raise InputError(f"the PC2 file is truncated: {len(data)} bytes of {need}.")
    if n_samples > MAX_FRAMES:
        raise InputError(f"the PC2 file has {n_samples} samples, too many to convert; trim it.")
    points = np.frombuffer(data, "<f4", n_samples * n_points * 3, 32).reshape(n_samples, n_points, 3)
    return points.astype(np.float32), np.arange(n_samples) * float(rate) / scene_fps


def read_mdd(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """(frames (T, P, 3) float32, times in seconds) of an MDD cache."""
    if len(data) < 8:
        raise InputError("the point cache is neither PC2 nor a complete MDD file (header too short).")
    n_frames, n_points = struct.unpack_from(">ii", data)
    if n_frames <= 0 or n_points <= 0:
        raise InputError(f"the MDD file has {n_frames} frames of {n_points} points; export at least one frame.")
    if n_frames > MAX_FRAMES:
        raise InputError(f"the MDD file has {n_frames} frames, too many to convert; trim it.")
    need = 8 + 4 * n_frames + n_frames * n_points * 12
    if len(data) < need:
        raise InputError(f"the MDD file is truncated: {len(data)} bytes of {need}.")
    times = np.frombuffer(data, ">f4", n_frames, 8).astype(np.float64)
    points = np.frombuffer(data, ">f4", n_frames * n_points * 3, 8 + 4 * n_frames).reshape(n_frames, n_points, 3)
    return points.astype(np.float32), times


def detect_axes(first: np.ndarray, rest: np.ndarray) -> str:
    """The AXIS_MAPS key that brings a cache frame closest to the rest mesh (RMS distance; identity on ties)."""
    first, rest = first.astype(np.float64), rest.astype(np.float64)
    errors = {k: float(np.sqrt(((f(first) - rest) ** 2).sum(1).mean())) for k, f in AXIS_MAPS.items()}
    best = min(errors, key=errors.get)
    return best if errors[best] < 0.999 * errors["none"] else "none"


def rate_of(times: np.ndarray) -> float | None:
    """Samples per second when the times increase strictly and evenly enough to trust, else None."""
    if len(times) < 2 or not np.isfinite(times).all():
        return None
    gaps = np.diff(times)
    if gaps.min() <= 0:
        return None
    rate = 1.0 / float(np.median(gaps))
    whole = round(rate)
    return float(whole) if abs(rate - whole) < 1e-3 * rate else round(rate, 3)


def resample(points: np.ndarray, times: np.ndarray, fps: float) -> np.ndarray:
    """Linear interpolation of (S, P, 3) samples at times to frames k / fps covering [times[0], times[-1]]."""
    t0, t1 = float(times[0]), float(times[-1])
    # Times are float32: a time within 1/1000 of a frame still makes that frame.
    n = int(math.floor((t1 - t0) * fps + 1e-3)) + 1
    if n > MAX_FRAMES:
        raise InputError(f"the point cache lasts {t1 - t0:.0f} s, too long to convert at {fps} fps; trim it.")
    if len(points) == 1:
        return points[:1]
    t = t0 + np.arange(n) / fps
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    u = np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0).astype(np.float32)[:, None, None]
    return points[k] * (1 - u) + points[k + 1] * u
