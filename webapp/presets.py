"""Form presets (the mobile one: small and light for phones) and the size a finished job would have with one."""

from __future__ import annotations

from converter.options import PRESETS
from webapp.jobstore import Job

__all__ = ["PRESETS", "estimate_sizes"]  # name -> (label, option values, description): the form's preset buttons


def estimate_sizes(job: Job) -> list[dict]:
    """For a finished SVG job: each preset's estimated SVG and SVGZ size, scaled by the triangles it keeps.

    The animated SVG's size grows about linearly with the triangles drawn (each carries its own keyframe
    values); the pixel size changes only the number of digits, which the estimate ignores.
    """
    result = job.result or {}
    outputs = result.get("outputs") or {}
    counts = (result.get("report") or {}).get("counts") or {}
    kept = counts.get("triangles_kept") or counts.get("triangles")
    if not outputs.get("svg") or not kept:
        return []
    out = []
    for name, (label, overrides, _) in PRESETS.items():
        budget = overrides.get("max_triangles")
        share = min(1.0, budget / kept) if budget else 1.0
        out.append({"name": name, "label": label, "svg": int(outputs["svg"] * share),
                    "svgz": int(outputs.get("svgz", 0) * share), "triangles": int(min(kept, budget or kept))})
    return out
