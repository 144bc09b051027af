"""Levels of articulation (section 12.4.3, Table 12.1): FAPs grouped per face region, reduced per level.

A group sends one value (its controlling FAP) for all its members: grouped FAPs share a region and a FAPU, and
when grouped by symmetry the controlling FAP is the one on the right of the face. Members not listed at a level
are removed. Counts per level match Table 12.1: 68 / 44 / 26 / 14 FAPs (head rotation 48-50 kept throughout).
"""

from __future__ import annotations

import numpy as np

from converter.errors import InputError
from converter.mpeg4.fap import FapStream
from converter.mpeg4.standard import N_FAPS

LEVELS = ("high", "medium", "low", "very-low")
REGIONS = {"high level": (1, 2), "jaw": tuple(range(3, 19)) + tuple(range(43, 48)) + tuple(range(51, 61)),
           "eyeballs": tuple(range(19, 31)), "eyebrows": tuple(range(31, 39)), "cheeks": (39, 40, 41, 42),
           "head": (48, 49, 50), "nose": (61, 62, 63, 64), "ears": (65, 66, 67, 68)}

_KEEP = [(1,), (2,), (48,), (49,), (50,)]
# Each group: (controlling FAP, members...). A FAP of the region that is in no group is removed at that level.
_GROUPS: dict[str, list[tuple[int, ...]]] = {
    "medium": _KEEP + [
        (4, 51), (5, 52), (6, 53), (7, 54), (8, 55), (9, 56), (10, 57), (11, 58), (12, 59), (13, 60),
        (3,), (14,), (15,), (17, 16), (18,), (43,), (44, 46), (45,), (47,),  # jaw: 19
        (19,), (20,), (21,), (22,), (24, 23), (26, 25), (28, 27), (30, 29),  # eyes: 8
        (32, 31), (34, 33, 35, 36), (38, 37),  # eyebrows: 3
        (39,), (40,), (41,), (42,),  # cheeks: 4
        (62, 61), (63,), (64,),  # nose: 3
        (66, 65), (68, 67),  # ears: 2
    ],
    "low": _KEEP + [
        (4, 51), (5, 52), (7, 6, 53, 54), (9, 8, 55, 56), (11, 10, 57, 58), (13, 12, 59, 60),
        (3,), (14,), (15,), (17, 16), (18,), (44, 46),  # jaw: 12
        (20, 19), (22, 21), (24, 23), (26, 25),  # eyes: 4
        (32, 31, 33, 34, 35, 36), (38, 37),  # eyebrows: 2
        (42, 41),  # cheeks: 1
        (66, 65), (68, 67),  # ears: 2
    ],
    "very-low": _KEEP + [
        (3,), (4, 8, 9, 51, 55, 56), (5, 10, 11, 52, 57, 58), (7, 6, 53, 54), (13, 12, 59, 60), (17, 16),  # jaw: 6
        (20, 19),  # eyes: 1
        (32, 31, 33, 34, 35, 36),  # eyebrows: 1
        (42, 41),  # cheeks: 1
    ],
}
_GROUPS["high"] = [(k,) for k in range(1, N_FAPS + 1)]


def groups(level: str) -> list[tuple[int, ...]]:
    """The FAP groups of a level, each (controlling FAP, other members...)."""
    if level not in _GROUPS:
        raise InputError(f"unknown level of articulation {level!r}; choose one of {', '.join(LEVELS)}.")
    return _GROUPS[level]


def fap_count(level: str) -> int:
    """How many FAP values a frame carries at this level (Table 12.1's totals)."""
    return len(groups(level))


def region_counts(level: str) -> dict[str, int]:
    """FAP values per region at this level (the rows of Table 12.1)."""
    return {name: sum(1 for g in groups(level) if g[0] in faps) for name, faps in REGIONS.items()}


def reduce(stream: FapStream, level: str) -> FapStream:
    """The stream at a level: one value per group (the controlling FAP's, else the first member set), rest dropped."""
    values = np.zeros_like(stream.values)
    mask = np.zeros_like(stream.mask)
    for g in groups(level):
        cols = np.array(g) - 1
        m = stream.mask[:, cols]
        first = np.argmax(m, axis=1)  # the controlling FAP when set, else the first member that is
        values[:, cols[0]] = stream.values[np.arange(stream.n_frames), cols[first]] * m.any(1)
        mask[:, cols[0]] = m.any(1)
    extra = {**stream.extra, "loa": level}
    return FapStream(stream.name, stream.fps, values, mask, extra)


def expand(stream: FapStream, level: str | None = None) -> FapStream:
    """Undo the grouping for playback: every member of a group takes its controlling FAP's value."""
    level = level or stream.extra.get("loa", "high")
    values = stream.values.copy()
    mask = stream.mask.copy()
    for g in groups(level):
        if len(g) > 1:
            c = g[0] - 1
            cols = np.array(g[1:]) - 1
            values[:, cols] = np.where(stream.mask[:, c:c + 1], stream.values[:, c:c + 1], 0.0)
            mask[:, cols] = stream.mask[:, c:c + 1]
    extra = {k: v for k, v in stream.extra.items() if k != "loa"}
    return FapStream(stream.name, stream.fps, values, mask, extra)
