"""SMIL text of the rigid groups (converter.encode.groups): a '<g>' with its band's animateTransform stack."""

from __future__ import annotations

import numpy as np

from converter.encode.groups import BandMotion
from converter.writers.svgtext import key_times
from converter.writers.svgtext import number as svg_number

CLOSE = "</g>"


def group_open(motion: BandMotion, n_frames: int, dur: str) -> str:
    """'<g>' plus the band's animateTransform stack (additive sum, in document order) for one run; a static
    translate on the group takes the median position out of the translate values (shorter numbers)."""
    out = ["<g>"]
    for a in motion.anims:
        values = a.values
        if a.kind == "translate" and len(values) > 1:
            # A static translate on the group holds the typical position; the (summed) animation only the rest.
            base = np.rint(np.median(values, axis=0)).astype(np.int64)
            out[0] = f'<g transform="translate({base[0]} {base[1]})">'
            values = values - base
        vals = ";".join(" ".join(svg_number(v, a.decimals) for v in row) for row in values.tolist())
        head = f'<animateTransform attributeName="transform" type="{a.kind}" additive="sum" dur="{dur}" '
        if len(a.frames) == 1 or len(a.frames) == n_frames + 1:  # a set, or evenly spaced: no keyTimes
            out.append(f'{head}repeatCount="indefinite" values="{vals}"/>')
            continue
        kt = ";".join(key_times(a.frames, n_frames, motion.time_decimals))
        out.append(f'{head}repeatCount="indefinite" keyTimes="{kt}" values="{vals}"/>')
    return "".join(out)
