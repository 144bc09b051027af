"""A cheap predictor of how an animated SVG plays: main-thread ms per frame in Chromium under 4x CPU throttling.

Calibrated by bench_playback on the capture-like face and the sample (2-core machine, software raster, shared):
a path costs its paint, a d animation re-lays its path every frame, and a (discrete) colour animation restyles
it at a cost that grows with the document's paths, and a shared colour (a gradient's animated stop) repaints the
paths that refer to it.
A class, not a promise: the measurements scatter widely on a shared machine, more for single runs.
"""

from __future__ import annotations

from collections.abc import Mapping

MS_PER_PATH = 0.02  # paint of one path, 4x throttling
MS_PER_D = 0.07  # one animated d
MS_PER_COLOR = 0.15  # one animated colour
MS_PER_COLOR_PATH = 6e-5  # and its growth with the document's paths
MS_PER_SHARED = 0.45  # one shared colour (a gradient stop's animation): its paths repaint (bench_palette_refs)
MS_PER_SHARED_PATH = 5e-4  # and its growth with the document's paths
CLASSES = ((1000 / 30, "plays smoothly on phones"),  # >= 30 fps at 4x (a mid-range phone)
           (1000 / 10, "plays smoothly on desktops, slowly on phones"))  # >= 10 fps at 4x, ~30+ at 1x
HEAVY = "heavy"


def predict_ms(counts: Mapping[str, int]) -> float:
    """Predicted main-thread ms per frame at 4x CPU throttling from a Report's counts."""
    paths = counts.get("paths", 0)
    return (MS_PER_PATH * paths + MS_PER_D * counts.get("animated_paths", 0)
            + counts.get("color_animations", 0) * (MS_PER_COLOR + MS_PER_COLOR_PATH * paths)
            + counts.get("shared_color_animations", 0) * (MS_PER_SHARED + MS_PER_SHARED_PATH * paths))


def playback_class(ms: float) -> str:
    """The playback class of a predicted ms per frame."""
    for limit, label in CLASSES:
        if ms <= limit:
            return label
    return HEAVY
