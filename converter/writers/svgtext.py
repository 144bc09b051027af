"""Number text for SVG attributes: the shortest form that parses back to the rounded value, and keyTimes."""

from __future__ import annotations

import re

import numba
import numpy as np

_MINUS_ZERO = re.compile(r"(?<=\x00)-0(?=\x00)")


def number(x: float, decimals: int) -> str:
    """x rounded to decimals, without trailing zeros or a leading zero ('.25', '-.5', '3', '0')."""
    return numbers(np.array([x], np.float64), decimals)[0]


def numbers(values: np.ndarray, decimals: int) -> list[str]:
    """number() of each value (flattened): one format call for all, trimmed by replacements over the joined text
    (str.replace; a regular expression costs a Python call per match). About half the cost of formatting and
    trimming each value on its own, joins included (a long capture's transforms and keyTimes hold millions)."""
    v = np.asarray(values, np.float64).ravel().tolist()
    if not v:
        return []
    text = "\x00" + (f"%.{int(decimals)}f\x00" * len(v)) % tuple(v)  # every item between two NULs
    for _ in range(decimals):  # one trailing zero a pass: at most the decimals, so never an integer's
        text = text.replace("0\x00", "\x00")
    if decimals > 0:
        text = text.replace(".\x00", "\x00")
    text = text.replace("\x000.", "\x00.").replace("\x00-0.", "\x00-.")
    return _MINUS_ZERO.sub("0", text)[1:-1].split("\x00")


def subpaths(rows: np.ndarray, closed: np.ndarray | None = None) -> list[str]:
    """Integer rows (K, D) as 'm' and the integers, a space between two but none before a minus sign (it
    separates them), then 'z' where closed (K,) (default: every row): 'm12 5-3 4 0-1z'. Compiled: Python's %
    formatting of every integer was most of the writer's text cost on long captures."""
    rows = np.ascontiguousarray(rows, np.int64)
    if not len(rows):
        return []
    shut = np.ones(len(rows), np.bool_) if closed is None else np.ascontiguousarray(closed, np.bool_)
    width = len(str(int(np.abs(rows).max()))) + 2  # sign or space, digits
    buf = np.empty(len(rows) * (3 + rows.shape[1] * width), np.uint8)
    return buf[:_subpaths(rows, shut, buf)].tobytes().decode("ascii").split("\x00")


@numba.njit(cache=True, nogil=True)
def _subpaths(rows, closed, buf):
    """subpaths() into buf (NUL between rows); returns the length written."""
    pos = 0
    for k in range(rows.shape[0]):
        if k:
            buf[pos] = 0
            pos += 1
        buf[pos] = 109  # m
        pos += 1
        for c in range(rows.shape[1]):
            v = rows[k, c]
            if v < 0:
                buf[pos] = 45  # -
                pos += 1
                v = -v
            elif c:
                buf[pos] = 32
                pos += 1
            n = 1
            x = v
            while x >= 10:
                x //= 10
                n += 1
            for i in range(n - 1, -1, -1):
                buf[pos + i] = 48 + v % 10
                v //= 10
            pos += n
        if closed[k]:
            buf[pos] = 122  # z
            pos += 1
    return pos


def key_times(frames: np.ndarray, n_frames: int, decimals: int | np.ndarray, snap: str = "nearest") -> list[str]:
    """keyTimes text of each frame index (frame k at k / T) with decimals (one, or one per frame).

    snap says how a time falls on the decimals' grid: 'nearest' rounds; a discrete change must show at frame k
    however a player rounds its clock, so 'early' puts it half a frame early ((k - 1/2) / T, rounded) and
    'floor' rounds down and 'ceil' up. Each distinct (frame, decimals) is formatted once."""
    frames = np.asarray(frames, np.int64)
    dec = np.broadcast_to(np.asarray(decimals, np.int64), frames.shape)
    out = np.empty(len(frames), object)
    for d in np.unique(dec).tolist():
        sel = dec == d
        uniq, inv = np.unique(frames[sel], return_inverse=True)
        q = 10**d
        if snap == "floor":
            units = (uniq * q) // n_frames
        elif snap == "ceil":
            units = -((-uniq * q) // n_frames)
        elif snap == "early":
            units = np.rint(np.maximum(uniq - 0.5, 0.0) * q / n_frames).astype(np.int64)
        elif snap == "nearest":
            units = np.rint(uniq * q / n_frames).astype(np.int64)
        else:
            raise ValueError(f"unknown snap {snap!r}")
        out[sel] = np.asarray(numbers(units / q, d), object)[inv]
    return out.tolist()


def digits(v: np.ndarray) -> np.ndarray:
    """Characters of each integer written in decimal (sign included)."""
    return 1 + (v < 0) + np.searchsorted(10 ** np.arange(1, 19, dtype=np.int64), np.abs(v), side="right")
