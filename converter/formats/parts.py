"""Part names from material/mesh/node names: the keywords loaders use to tell skin, eyes, teeth, ... apart."""

from __future__ import annotations

import re

import numpy as np

from converter.animation import DEFAULT_PART_COLORS, Part

# Checked in order: "eyelash" must become lashes before "eye" can claim it, "iris" before "eye".
_KEYWORDS: tuple[tuple[str, re.Pattern], ...] = (
    ("lashes", re.compile(r"lash|brow[\W_]*hair|eyebrow", re.I)),
    ("iris", re.compile(r"iris|pupil|cornea", re.I)),
    ("teeth", re.compile(r"teeth|tooth", re.I)),
    ("mouth", re.compile(r"tongue|mouth|gum|oral", re.I)),
    ("eye", re.compile(r"eye|sclera", re.I)),
)


def part_name(*labels: str | None) -> str:
    """The part a primitive belongs to from its names (first label that matches a keyword wins), else skin."""
    for label in labels:
        if not label:
            continue
        for part, pattern in _KEYWORDS:
            if pattern.search(label):
                return part
    return "skin"


def collect_parts(keys: list[tuple[str, tuple[float, float, float] | None]]) -> tuple[tuple[Part, ...], np.ndarray]:
    """Parts for (name, colour or None) keys in first-seen order, merging equal ones; returns (parts, id per key)."""
    parts: list[Part] = []
    index: dict[tuple, int] = {}
    ids = []
    for name, color in keys:
        rgb = tuple(float(c) for c in (color if color is not None else DEFAULT_PART_COLORS[name]))
        key = (name, rgb)
        if key not in index:
            index[key] = len(parts)
            parts.append(Part(name, rgb))  # type: ignore[arg-type]
        ids.append(index[key])
    return tuple(parts), np.asarray(ids, np.int32)


def parts_for_groups(groups: list[str], group_of_face: np.ndarray,
                     colors: dict[str, tuple] | None = None) -> tuple[tuple[Part, ...], np.ndarray]:
    """Parts for the OBJ groups that hold triangles, named by keyword and coloured from colors (else default)."""
    colors = colors or {}
    used = np.unique(group_of_face)
    parts, ids = collect_parts([(part_name(groups[g]), colors.get(groups[g])) for g in used])
    lookup = np.zeros(len(groups), np.int32)
    lookup[used] = ids
    return parts, lookup[group_of_face]
