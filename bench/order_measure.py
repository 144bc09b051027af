"""Measuring drawing order (converter.encode.order) against a z-buffer, for bench_svg and the order tests.

``order_error``: pyrender renders triangle ids, resvg renders the same frame's painter's-order SVG with ids as
colours, and the covered interior pixels whose front triangle differs are counted. ``robust_order`` is the
alternative order the benchmark compares with the default.
"""

from __future__ import annotations

import io

import numpy as np
import resvg_py
from PIL import Image

from converter import render
from converter.encode.order import DrawList
from converter.sheet import Sheet


def robust_order(sheet: Sheet, tris: np.ndarray) -> np.ndarray:
    """tris sorted back to front by mean centroid depth over the frames where each is visible (stable)."""
    cen = sheet.depth[:, sheet.faces[tris]].mean(axis=2)  # (T, K)
    vis = sheet.visible[:, tris]
    mean = np.where(vis, cen, 0).sum(axis=0) / np.maximum(vis.sum(axis=0), 1)
    return tris[np.argsort(-mean, kind="stable")].astype(np.int32)


def id_svg(sheet: Sheet, dl: DrawList, frame: int) -> str:
    """A still SVG of one frame with every path filled by its triangle id + 1 as a colour, no anti-aliasing."""
    show = dl.active[frame]
    tris = dl.triangles[show]
    ids = tris.astype(np.int64) + 1
    xy = sheet.xy[frame][sheet.faces[tris]].reshape(-1, 6)
    body = "".join(
        f'<path d="M{r[0]:.3f} {r[1]:.3f}L{r[2]:.3f} {r[3]:.3f}L{r[4]:.3f} {r[5]:.3f}Z" fill="#{c:06x}"/>'
        for r, c in zip(xy.tolist(), ((ids & 255) << 16 | ((ids >> 8) & 255) << 8 | (ids >> 16) & 255).tolist()))
    w, h = sheet.camera.width, sheet.camera.height
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" '
            f'shape-rendering="crispEdges">{body}</svg>')


def order_error(frames3d: np.ndarray, sheet: Sheet, dl: DrawList, which: list[int]) -> dict[str, float]:
    """Share of the interior pixels (the z-buffer shows one triangle in their 3x3 neighbourhood) covered in both
    renders whose front triangle in the painter's SVG (resvg, ids as colours) is not the z-buffer's (pyrender);
    per-frame max and mean over the frames `which`."""
    pyrender = render._pyrender()
    f = sheet.faces.shape[0]
    ids = np.arange(1, f + 1, dtype=np.int64)
    rgba = np.stack([ids & 255, (ids >> 8) & 255, (ids >> 16) & 255, np.full(f, 255)], axis=1).astype(np.uint8)
    fracs = []
    with render.offscreen(sheet.camera.width, sheet.camera.height) as r:
        for k in which:
            scene = render._scene(sheet.camera)
            scene.add(render._mesh(frames3d[k], sheet.faces, rgba, smooth=False))
            color, _ = r.render(scene, flags=pyrender.RenderFlags.FLAT)
            px = color.astype(np.int64)
            ref = px[..., 0] | (px[..., 1] << 8) | (px[..., 2] << 16)
            png = bytes(resvg_py.svg_to_bytes(svg_string=id_svg(sheet, dl, k)))
            im = np.asarray(Image.open(io.BytesIO(png)).convert("RGBA")).astype(np.int64)
            got = np.where(im[..., 3] > 0, im[..., 0] | (im[..., 1] << 8) | (im[..., 2] << 16), 0)
            pad = np.pad(ref, 1, mode="edge")
            interior = np.ones(ref.shape, bool)  # multisampling blends ids on edges: judge interior pixels only
            for dy in range(3):
                for dx in range(3):
                    interior &= pad[dy:dy + ref.shape[0], dx:dx + ref.shape[1]] == ref
            valid = interior & (ref > 0) & (ref <= f) & (got > 0)
            fracs.append(float((got[valid] != ref[valid]).mean()) if valid.any() else 0.0)
    return {"max": max(fracs), "mean": float(np.mean(fracs)), "frames": len(fracs)}
