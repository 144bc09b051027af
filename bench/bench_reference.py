"""Real files against three.js: does each load, how long it takes, how big it is, how close it plays to three.js."""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from playwright.sync_api import sync_playwright

from converter.convert import convert
from converter.errors import InputError
from converter.formats.gltf import parse_container
from converter.formats.ictfacekit import load_ict_head
from converter.options import ConversionOptions
from tests.conftest import CHROMIUM_ARGS, SAMPLE, SHARED_DATA, chromium_path
from tests.reference import robot, skinned_ict, threejs

TITLE = "Real files against three.js"


def clip_names(path: Path) -> list[str]:
    """The glTF's animation names (index when unnamed)."""
    doc, _ = parse_container(path.read_bytes(), path.name)
    return [str(a.get("name") or i) for i, a in enumerate(doc.get("animations") or [])]


def cases() -> list[tuple[Path, int | None]]:
    """(file, clip) per real glTF with a mesh and per clip when facesvg can pick one, else (file, None)."""
    pick = "animation" in {f.name for f in dataclasses.fields(ConversionOptions)}
    out = []
    for path in [SAMPLE, *sorted(p for p in (SHARED_DATA / "real").glob("*") if p.suffix in (".glb", ".gltf", ".vrm"))]:
        doc, _ = parse_container(path.read_bytes(), path.name)
        if not doc.get("meshes"):
            continue
        n = len(doc.get("animations") or [])
        out += [(path, c) for c in range(n)] if pick and n > 1 else [(path, None)]
    return out


def row(browser, path: Path, clip: int | None, label: str | None = None) -> str:
    """One table row: convert at the default options (that clip), then compare 5 frames with three.js."""
    names = clip_names(path)
    label = label or (path.name if clip is None else f"{path.name} [{names[clip]}]")
    if clip is None and len(names) > 1:
        label += f" [{names[0]}: the first of {len(names)} clips]"
    options = ConversionOptions() if clip is None else ConversionOptions.from_mapping({"animation": str(clip)})
    prepared = []
    t = time.perf_counter()
    try:
        result = convert(path, options, on_prepared=prepared.append)
    except InputError as exc:
        return f"| {label} | no: {exc} | | | | | | | |"
    secs = time.perf_counter() - t
    anim = prepared[0]
    meta = threejs.svg_metadata(result.data)
    frames = threejs.spread_frames(meta["frames"])
    played = "all" if len(names) <= 1 else [clip or 0]
    cmp = threejs.compare(browser, path, result.data, frames, played)
    srgb = threejs.compare(browser, path, result.data, frames[:1], played, linear=False) if cmp.colour[0] is not None \
        else None
    colour = "n/a (texture or no colour)" if cmp.colour[0] is None else \
        f"{max(cmp.colour):.1f} / {srgb.colour[0]:.1f}"
    gouraud = ConversionOptions.from_mapping({**({} if clip is None else {"animation": str(clip)}),
                                             "shading": "gouraud"})
    try:
        g = threejs.compare(browser, path, convert(path, gouraud).data, frames, played)
        g_iou = f"{g.min_iou:.3f}"
    except InputError as exc:
        g_iou = f"no: {exc}"
    return (f"| {label} | yes | {anim.n_frames} | {anim.n_faces:,} | {secs:.1f} | {len(result.data):,} | "
            f"{cmp.min_iou:.3f} | {g_iou} | {colour} |")


def run() -> str:
    if chromium_path() is None or threejs.missing():
        return f"Not measured: Chromium or three.js missing ({threejs.missing() or 'apt-get install chromium'})."
    rows = ["| file | loads? | frames | triangles | convert s | SVG bytes | min IoU vs three.js | Gouraud min IoU | "
            "colour diff (linear / sRGB) |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            rows += [row(browser, path, clip) for path, clip in cases()]
            with tempfile.TemporaryDirectory() as tmp:  # tests/reference/skinned_ict.py, as the reference test builds it
                path = Path(tmp) / "skinned_ict.glb"
                path.write_bytes(skinned_ict.skinned_face(load_ict_head(SHARED_DATA / "ict_facekit")))
                rows.append(row(browser, path, None, "generated skinned ICT head (root/neck/head/jaw, 3 morph targets)"))
                path = Path(tmp) / "robot.glb"
                path.write_bytes(robot.robot())
                rows.append(row(browser, path, None, "generated thin-limbed skinned robot (tests/reference/robot.py)"))
        finally:
            browser.close()
    return (f"`facesvg convert` at the default options (512 px) on the bundled sample, every glTF/VRM with a mesh in "
            "../shared/data/real, the generated skinned ICT head (tests/reference/skinned_ict.py) and the generated "
            "thin-limbed robot (tests/reference/robot.py), one run each (convert s: load to SVG bytes, wall time on a shared machine). "
            f"three.js {threejs.three_version()} (tests/reference) plays the same file (the same clip) in headless "
            "Chromium with the camera of the SVG's metadata; min IoU is the worst silhouette IoU of 5 frames spread "
            "over the animation, for the default (flat) SVG and the Gouraud one (`--shading gouraud`). Colour diff: mean |RGB| in 8-bit levels inside both silhouettes, shaded with our "
            "light rig, where the file's colours are factors or vertex colours; 'linear' compares before three.js's "
            "sRGB output transform (the colours we read), 'sRGB' after it (what a three.js page shows, frame 0).\n\n"
            + "\n".join(rows))


if __name__ == "__main__":
    print(run())
