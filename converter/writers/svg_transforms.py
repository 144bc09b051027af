"""SMIL text of the rigid groups (converter.encode.groups): a '<g>' with its band's animateTransform stack."""

from __future__ import annotations

from converter.encode.groups import BandMotion
from converter.writers.svgtext import key_times, numbers

CLOSE = "</g>"
IDENTITY = {"translate": [0.0, 0.0], "rotate": [0.0], "skewX": [0.0], "scale": [1.0, 1.0]}


def group_open(motion: BandMotion, n_frames: int, dur: str) -> str:
    """'<g>' plus the band's animateTransform stack for one run.

    The static transform is the stack's frame-0 value, so a renderer that ignores SMIL (resvg, CairoSVG,
    rsvg-convert, Inkscape, thumbnailers) draws frame 0; the first animation replaces it and the others are
    summed onto that (document order), which is the same played transform. Identity terms are left out."""
    first, anims = [], []
    for i, a in enumerate(motion.anims):
        nums, width = numbers(a.values, a.decimals), a.values.shape[1]
        rows = [" ".join(nums[j:j + width]) for j in range(0, len(nums), width)]
        if a.values[0].tolist() != IDENTITY[a.kind]:
            first.append(f"{a.kind}({rows[0]})")
        additive = ' additive="sum"' if i else ""
        head = f'<animateTransform attributeName="transform" type="{a.kind}"{additive} dur="{dur}" '
        if len(a.frames) == 1 or len(a.frames) == n_frames + 1:  # a set, or evenly spaced: no keyTimes
            anims.append(f'{head}repeatCount="indefinite" values="{";".join(rows)}"/>')
            continue
        kt = ";".join(key_times(a.frames, n_frames, motion.time_decimals))
        anims.append(f'{head}repeatCount="indefinite" keyTimes="{kt}" values="{";".join(rows)}"/>')
    opening = f'<g transform="{" ".join(first)}">' if first else "<g>"
    return opening + "".join(anims)
