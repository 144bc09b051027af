"""Animated flat-shaded SVG: one <path> per kept triangle, back to front, SMIL-animated d, visibility and fill."""

from __future__ import annotations

import json
from xml.sax.saxutils import escape

import numpy as np

from converter.options import ConversionOptions, Report
from converter.sheet import Sheet

FORMAT_VERSION = 1


def hex_colors(rgb: np.ndarray) -> np.ndarray:
    """Display-space 0..1 RGB (..., 3) to '#rrggbb' strings."""
    q = np.clip(np.round(np.asarray(rgb) * 255), 0, 255).astype(np.int64)
    code = (q[..., 0] << 16) | (q[..., 1] << 8) | q[..., 2]
    return np.char.add("#", np.char.zfill(np.char.lower(np.char.mod("%x", code)), 6))


def key_times(frames: np.ndarray, n_frames: int) -> str:
    """keyTimes for frame indices: frame k at k / T of the loop."""
    return ";".join(_num(k / n_frames, 6) for k in frames)


def _num(x: float, decimals: int) -> str:
    s = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def raw_path_values(tri_xy: np.ndarray, decimals: int = 2) -> list[str]:
    """Per frame 'M x,y L x,y L x,y Z' of one triangle, (T, 3, 2) -> T strings (the chapter's encoding)."""
    flat = np.round(tri_xy.reshape(tri_xy.shape[0], 6), decimals)
    fmt = f"M%.{decimals}f,%.{decimals}fL%.{decimals}f,%.{decimals}fL%.{decimals}f,%.{decimals}fZ"
    return [fmt % tuple(row) for row in flat]


def discrete_animation(attribute: str, values: list[str], n_frames: int, dur: str) -> str:
    """A discrete <animate> that changes only where the value changes; '' when it never does."""
    changes = [0] + [k for k in range(1, n_frames) if values[k] != values[k - 1]]
    if len(changes) == 1:
        return ""
    return (
        f'<animate attributeName="{attribute}" calcMode="discrete" dur="{dur}" repeatCount="indefinite" '
        f'keyTimes="{key_times(np.array(changes), n_frames)}" values="{";".join(values[k] for k in changes)}"/>'
    )


def path_animation(values: list[str], frames: np.ndarray, n_frames: int, dur: str) -> str:
    """A linear <animate> of d through the given key frames; frame k shows at t = k / fps."""
    frames = list(frames)
    vals = [values[i] for i in range(len(frames))]
    if frames[-1] != n_frames:  # SMIL's linear keyTimes must end at 1: hold the last key to the loop's end
        frames.append(n_frames)
        vals.append(vals[-1])
    return (
        f'<animate attributeName="d" dur="{dur}" repeatCount="indefinite" '
        f'keyTimes="{key_times(np.array(frames), n_frames)}" values="{";".join(vals)}"/>'
    )


def metadata(sheet: Sheet, options: ConversionOptions, report: Report, extra: dict | None = None) -> str:
    """The <metadata id="facesvg"> element: JSON with everything needed to re-project and check the output."""
    doc = {
        "format": "facesvg",
        "version": FORMAT_VERSION,
        "frames": sheet.n_frames,
        "fps": sheet.fps,
        "duration": sheet.duration,
        "viewport": [sheet.camera.width, sheet.camera.height],
        "camera": sheet.camera.to_json(),
        "source_sha256": sheet.info.get("source_sha256", ""),
        "source_frames": sheet.info.get("source_frames", [0, sheet.n_frames]),
        "options": options.to_json(),
        "counts": {k: v for k, v in sheet.info.items() if isinstance(v, int)},
        "triangle_order": [int(i) for i in sheet.order],
    }
    if extra:
        doc.update(extra)
    return f'<metadata id="facesvg">{escape(json.dumps(doc, sort_keys=True, separators=(",", ":")))}</metadata>'


def write(sheet: Sheet, options: ConversionOptions, report: Report) -> bytes:
    """The animated SVG, every frame encoded (the raw encoding) or the still of options.frame."""
    t = sheet.n_frames
    w, h = sheet.camera.width, sheet.camera.height
    dur = f"{_num(sheet.duration, 6)}s"
    colors = hex_colors(sheet.face_rgb)  # (T, F)
    frame_range = [options.frame] if options.frame is not None else None
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">',
        metadata(sheet, options, report),
        f"<title>{escape(sheet.name)}</title>",
        '<g stroke-linejoin="round">',
    ]
    for f in sheet.order:
        tri = sheet.xy[:, sheet.faces[f]]
        if frame_range is not None:
            k = frame_range[0]
            if not sheet.visible[k, f]:
                continue
            d = raw_path_values(tri[k : k + 1])[0]
            out.append(f'<path id="f{f}" d="{d}" fill="{colors[k, f]}" stroke="{colors[k, f]}" stroke-width="0.5"/>')
            continue
        vis = ["visible" if v else "hidden" for v in sheet.visible[:, f]]
        values = raw_path_values(tri)
        fills = list(colors[:, f])
        first = int(np.argmax(sheet.visible[:, f]))
        anims = [
            path_animation(values, np.arange(t), t, dur) if t > 1 else "",
            discrete_animation("visibility", vis, t, dur),
            discrete_animation("fill", fills, t, dur),
            discrete_animation("stroke", fills, t, dur),
        ]
        body = "".join(anims)
        attrs = f'id="f{f}" d="{values[first]}" fill="{fills[0]}" stroke="{fills[0]}" stroke-width="0.5"'
        if not sheet.visible[0, f]:
            attrs += ' visibility="hidden"'
        out.append(f"<path {attrs}>{body}</path>" if body else f"<path {attrs}/>")
    out.append("</g></svg>\n")
    return "\n".join(out).encode("utf-8")
