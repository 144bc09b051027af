"""A cheap predictor of how an animated SVG plays: main-thread ms per frame in Chromium under 4x CPU throttling.

Calibrated by bench_playback and bench_default_playback (whose 4x cells check it) on the capture-like face and the
sample (2-core machine, software raster, shared): a path costs its paint, a d animation re-lays its path every
frame, a (discrete) colour animation restyles it at a cost that grows with the document's paths, and a shared
colour (a gradient's animated stop) restyles the paths that refer to it, at a cost that grows with the document.
A class, not a promise: the measurements scatter widely on a shared machine, more for single runs.
"""

from __future__ import annotations

from collections.abc import Mapping

MS_PER_PATH = 0.02  # paint of one path, 4x throttling
MS_PER_D = 0.07  # one animated d
MS_PER_COLOR = 0.15  # one animated colour
MS_PER_COLOR_PATH = 6e-5  # and its growth with the document's paths
MS_PER_SHARED_PATH = 2.2e-4  # one shared colour (a gradient stop's animation), per path of the document: it
# restyles the paths that refer to it, and it costs in proportion to the document (bench_default_playback's 4x cells)
CLASSES = ((1000 / 30, "plays smoothly on phones"),  # >= 30 fps at 4x (a mid-range phone)
           (1000 / 10, "plays smoothly on desktops, slowly on phones"))  # >= 10 fps at 4x, ~30+ at 1x
HEAVY = "heavy"


def predict_ms(counts: Mapping[str, int]) -> float:
    """Predicted main-thread ms per frame at 4x CPU throttling from a Report's counts."""
    paths = counts.get("paths", 0)
    return (MS_PER_PATH * paths + MS_PER_D * counts.get("animated_paths", 0)
            + counts.get("color_animations", 0) * (MS_PER_COLOR + MS_PER_COLOR_PATH * paths)
            + counts.get("shared_color_animations", 0) * MS_PER_SHARED_PATH * paths)


def playback_class(ms: float) -> str:
    """The playback class of a predicted ms per frame."""
    for limit, label in CLASSES:
        if ms <= limit:
            return label
    return HEAVY


def describe(ms: float) -> str:
    """The class of a predicted ms per frame in words for a user: the class, the frame rate it predicts on a
    mid-range phone (4x), and what plays faster when the file is not for phones."""
    label = playback_class(ms)
    if ms <= CLASSES[0][0]:
        return label
    fps = 1000.0 / max(ms, 1e-9)
    return f"{label} (~{fps:.2g} fps on a mid-range phone; --preset mobile or --to player play smoothly there)"
