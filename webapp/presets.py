"""Form presets (the mobile one: small and light for phones) and the size a finished job would have with one."""

from __future__ import annotations

from converter.options import PRESETS, option_fields
from webapp.jobstore import Job

__all__ = ["PRESETS", "estimate_sizes", "has_preset"]  # name -> (label, option values, description)

# The mobile version's SVG bytes from the finished job's: OVERHEAD + SHARE x svg x (min(K, TRIANGLES) / K) **
# EXPONENT, K the triangles it drew. The preset keeps the fewest triangles that hold its error bound at 256 px (a
# bounded count on a head, whatever the source had), and bytes shrink more slowly than triangles (its
# merged paths share keys); its coarser tolerance and static colours take the rest; OVERHEAD is what every SVG
# carries (metadata, style). Fitted on default-option flat SVG jobs against the Mobile preset's made size, on real
# files and the sample: `python bench/run.py bench_estimates` measures it (BENCHMARKS.md). Re-fit when the preset's
# simplification changes.
OVERHEAD = 1400
SHARE = 0.48
TRIANGLES = 1200
EXPONENT = 0.7
# The options the model was fitted at (their defaults): a job made otherwise gets no figure, not a wrong one.
FITTED_AT = ("size", "tolerance", "color_tolerance", "max_animations", "max_triangles", "shading", "raw")


def has_preset(job: Job, name: str) -> bool:
    """True when the job was made with that preset, named or with every one of its values."""
    options = job.options or {}
    return options.get("preset") == name or all(options.get(k) == v for k, v in PRESETS[name].values.items())


def estimate_sizes(job: Job) -> list[dict]:
    """For a finished SVG job: each preset's version it was not made with, and its SVG size (bytes) by the fitted
    model above when the job was made at the options it was fitted at (else None)."""
    result = job.result or {}
    outputs = result.get("outputs") or {}
    counts = (result.get("report") or {}).get("counts") or {}
    kept = counts.get("triangles_kept") or counts.get("triangles")
    options = job.options or {}
    if not outputs.get("svg") or not isinstance(kept, int) or kept <= 0 or options.get("to", "svg") != "svg":
        return []
    defaults = {spec.name: spec.default for spec in option_fields()}
    fitted = all(options.get(k, defaults[k]) == defaults[k] for k in FITTED_AT)
    out = []
    for name, (label, _, _) in PRESETS.items():
        if has_preset(job, name):
            continue
        size = int(OVERHEAD + SHARE * outputs["svg"] * (min(kept, TRIANGLES) / kept) ** EXPONENT) if fitted \
            else None
        out.append({"name": name, "label": label, "svg": size})
    return out
