"""Which glTF animations play: a named or numbered clip, all of them, or by default the first take.

A take is a clip plus the later clips over the same time range whose targets are disjoint from the clips already
in it: the layout of exporters that write one animation per node (head, each eye, the morph weights) for what was
recorded as one performance. By default the first take plays (and a note names the clips it skipped); a name or
index plays that clip alone; "all" plays every take one after another, each from its own time 0.
"""

from __future__ import annotations

import numpy as np

from converter.errors import InputError

Tracks = dict[tuple[int, str], tuple[np.ndarray, np.ndarray, str]]
"""(node, path) -> (key times, values (keys, C), interpolation) of one animation."""

ALL = "all"


def time_range(tracks: Tracks) -> tuple[float, float]:
    """(first, last) key time over a clip's channels; (0, 0) for a clip with none."""
    if not tracks:
        return 0.0, 0.0
    return (min(float(t[0]) for t, _, _ in tracks.values()), max(float(t[-1]) for t, _, _ in tracks.values()))


def same_range(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether two clips span the same times within half a 30 fps frame or 1% of their length."""
    tol = max(1 / 60, 0.01 * max(a[1] - a[0], b[1] - b[0]))
    return abs(a[0] - b[0]) <= tol and abs(a[1] - b[1]) <= tol


def clip_label(index: int, name: str | None) -> str:
    """How notes and errors name a clip: its index and name."""
    return f"{index} '{name}'" if name else str(index)


def takes(clips: list[Tracks]) -> list[list[int]]:
    """Clips grouped into takes in file order: each clip joins the first take it fits (same range, disjoint targets)."""
    out: list[tuple[list[int], set, tuple[float, float]]] = []
    for j, tracks in enumerate(clips):
        span = time_range(tracks)
        for take, used, first in out:
            if tracks and same_range(span, first) and not used & set(tracks):
                take.append(j)
                used |= set(tracks)
                break
        else:
            out.append(([j], set(tracks), span))
    return [take for take, _, _ in out]


def choose(clips: list[Tracks], names: list[str | None], choice: str | None,
           file_name: str) -> tuple[list[list[int]], list[str]]:
    """(takes to play one after another, each a list of clips played together; notes) for --animation."""
    if not clips:
        if choice is not None and str(choice).strip().lower() != ALL:
            raise InputError(f"{file_name} has no animations, so --animation {choice} cannot be played; leave it out.")
        return [[]], []
    if choice is None:
        take = takes(clips)[0]
        rest = [j for j in range(len(clips)) if j not in take]
        if not rest:
            return [take], []
        played = " + ".join(clip_label(j, names[j]) for j in take)
        others = ", ".join(clip_label(j, names[j]) for j in rest)
        return [take], [f"{file_name}: played animation {played}; it also has {others} "
                        "(choose with --animation NAME|INDEX|all)."]
    choice = str(choice).strip()
    if choice.lower() == ALL:
        return takes(clips), []
    if choice in names:
        return [[names.index(choice)]], []
    if choice.isdigit() and int(choice) < len(clips):
        return [[int(choice)]], []
    listed = ", ".join(clip_label(j, names[j]) for j in range(len(clips)))
    raise InputError(f"{file_name} has no animation {choice!r}; choose --animation from {listed}, or all.")


def summaries(clips: list[Tracks], names: list[str | None], node_label) -> list[dict]:
    """Per clip, for `facesvg info`: index, name, duration (s), channel count, targets as 'node.path'."""
    out = []
    for j, tracks in enumerate(clips):
        start, end = time_range(tracks)
        out.append({"index": j, "name": names[j], "start": round(start, 4), "duration": round(end, 4),
                    "channels": len(tracks), "targets": sorted(f"{node_label(n)}.{p}" for n, p in tracks)})
    return out
