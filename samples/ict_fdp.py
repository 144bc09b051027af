"""The FDP of the ICT FaceKit neutral head (dataset tooling for samples/make_fdp.py, tests and bench)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from converter.formats.ictfacekit import EYEBALL_LEFT, EYEBALL_RIGHT, load_ict_head
from converter.mpeg4.facepoints import MULTIPIE_TO_FDP, complete_points, ear_points, nearest
from converter.mpeg4.fdp import Fdp, fapu_from_points


def ict_fdp(folder: str | Path) -> Fdp:
    """FDP of the ICT FaceKit neutral head: 68 landmark vertex ids mapped to feature points, plus rules and parts."""
    head = load_ict_head(folder)
    v = head.vertices.astype(np.float64)
    lm = head.landmarks
    skin_part = [i for i, p in enumerate(head.parts) if p.name == "skin"][0]
    skin = np.unique(head.faces[head.part_ids == skin_part])
    pts: dict[str, int] = {}
    for fp, ids in MULTIPIE_TO_FDP.items():
        pts[fp] = int(lm[ids[0]]) if len(ids) == 1 else nearest(v, skin, v[lm[list(ids)]].mean(0))
    parts: dict[str, list[int]] = {
        "left_eye": list(range(*EYEBALL_LEFT)),
        "right_eye": list(range(*EYEBALL_RIGHT)),
        "upper_teeth": list(range(17039, 19247)),  # vertex ranges from the FaceKit README
        "lower_teeth": list(range(19247, 21451)),
    }
    # Gums and tongue are one mesh: above the bite goes with the skull, near the lower teeth with the jaw,
    # the rest is the tongue.
    mouth = np.arange(14062, 17039)
    upper = np.asarray(parts["upper_teeth"])
    lower = np.asarray(parts["lower_teeth"])
    bite = (v[upper, 1].min() + v[lower, 1].max()) / 2
    d_low, _ = cKDTree(v[lower]).query(v[mouth])
    above = v[mouth, 1] > bite
    gums_low = ~above & (d_low < 0.3)
    parts["upper_teeth"] += mouth[above].tolist()
    parts["lower_teeth"] += mouth[gums_low].tolist()
    tongue = mouth[~above & ~gums_low]
    parts["tongue"] = tongue.tolist()
    pts["6.1"] = int(tongue[np.argmax(v[tongue, 2])])
    centre = v[tongue].mean(0)
    top = tongue[v[tongue, 1] > np.percentile(v[tongue, 1], 80)]
    pts["6.2"] = nearest(v, top, centre)
    pts["6.3"] = int(tongue[np.argmax(v[tongue, 0])])
    pts["6.4"] = int(tongue[np.argmin(v[tongue, 0])])
    inc_up = upper[np.abs(v[upper, 0]) < 0.5]
    inc_lo = lower[np.abs(v[lower, 0]) < 0.5]
    pts["9.10"] = int(inc_up[np.argmin(v[inc_up, 1])])
    pts["9.11"] = int(inc_lo[np.argmax(v[inc_lo, 1])])
    pts = complete_points(v, skin, pts, parts)
    ears = ear_points(v, skin)
    pts.update({k: i for k, i in ears.items() if k not in pts})
    fdp = Fdp(pts, parts, {}, {}, len(v), "ICT FaceKit neutral head: Multi-PIE landmarks + geometric rules "
              "(converter/mpeg4/facepoints.py)")
    fdp.fapu = fapu_from_points(v, fdp.point_positions(v))
    return fdp
