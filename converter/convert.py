"""The one path through facesvg: load -> 3D stages -> extract -> write, with a Report and atomic output."""

from __future__ import annotations

import gzip
import hashlib
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from converter import extract as extraction
from converter import formats
from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.options import ConversionOptions, Progress, Report, no_progress


@dataclass
class Result:
    """A finished conversion: the output bytes, its media type and extension, and the Report."""

    data: bytes
    media_type: str
    extension: str
    report: Report


def load(path: str | Path, options: ConversionOptions, cache: str | Path | None = None,
         progress: Progress = no_progress) -> FaceAnimation:
    """Read the input file named by path (plus an optional point cache) with the options' fps."""
    if options.weights:  # the input is a face with named morph targets, animated by the capture
        from converter.blendshapes import drive_file

        return drive_file(path, options.weights, fps=options.fps, progress=lambda s, f: progress(s, 0.05 * f))
    return formats.load(path, fps=options.fps, cache=cache)


def prepare(anim: FaceAnimation, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> FaceAnimation:
    """The optional 3D stages in order: FAP driving, frame range, cloning, triangle budget."""
    if "weights" in anim.extras:  # what the weight capture matched, from load()
        report.counts.update(anim.extras["weights"]["counts"])
        report.warnings.extend(anim.extras["weights"]["warnings"])
    if options.fap and options.to != "fap2d":  # the fap2d package carries the stream itself
        from converter import mpeg4

        t = time.perf_counter()
        anim = mpeg4.drive(anim, options.fap, options.fdp, fps=options.fps)
        report.timings["fap"] = time.perf_counter() - t
        progress("fap", 0.05)
    if options.start or options.end is not None:
        anim = anim.sliced(options.start, options.end)
    if options.clone_target:
        from converter import cloning

        t = time.perf_counter()
        target = formats.load(options.clone_target)
        anim = cloning.clone(anim, target, options.clone_method, keys=options.clone_keys,
                             correspondences=options.correspondences)
        report.timings["clone"] = time.perf_counter() - t
        progress("clone", 0.08)
    if options.max_triangles is not None and options.max_triangles < anim.n_faces:
        from converter import simplify

        t = time.perf_counter()
        anim = simplify.simplify(anim, options.max_triangles, report, options=options)
        report.timings["simplify"] = time.perf_counter() - t
        progress("simplify", 0.1)
    if options.smooth:
        from converter import smoothing

        anim = smoothing.apply(anim, options, report)
    return anim


def convert_animation(
    anim: FaceAnimation, options: ConversionOptions, progress: Progress = no_progress, source_sha256: str = "",
    on_prepared: Callable[[FaceAnimation], None] | None = None,
) -> Result:
    """Convert an in-memory FaceAnimation with the options; the library's main entry point."""
    report = Report()
    anim = prepare(anim, options, report, progress)
    if on_prepared is not None:  # callers that also need the 3D animation (the web UI's prerender)
        on_prepared(anim)
    if options.to == "fap2d":
        from converter.writers import fap2d

        return fap2d.convert(anim, options, report, progress)
    if options.frame is not None and not 0 <= options.frame < anim.n_frames:
        raise InputError(f"--frame {options.frame} is outside 0..{anim.n_frames - 1}; choose a frame inside it.")
    t = time.perf_counter()
    camera = extraction.fit_camera(anim, options.size, options.yaw, options.pitch, options.fov, options.ortho)
    sheet = extraction.extract(
        anim, camera, neutral=options.neutral_frame, occlusion=options.occlusion,
        progress=lambda s, f: progress(s, 0.1 + 0.5 * f),
        occlusion_frames=None if options.frame is None else (options.frame,),  # a still: only its frame counts
    )
    if not sheet.kept.any():
        raise InputError("no triangle is ever visible from this camera (all face away or lie outside the view); "
                         "check --yaw/--pitch or the mesh's winding.")
    sheet.info["source_sha256"] = source_sha256
    sheet.info["source_frames"] = [options.start, options.start + anim.n_frames]
    report.timings["extract"] = time.perf_counter() - t
    report.counts.update({k: v for k, v in sheet.info.items() if isinstance(v, int)})
    from converter.writers import writer_for

    write = writer_for(options)
    t = time.perf_counter()
    progress("write", 0.6)
    data = write(sheet, options, report)
    report.sizes["svg"] = len(data)
    if options.svgz:
        data = gzip.compress(data, mtime=0)
    report.timings["write"] = time.perf_counter() - t
    report.sizes["output"] = len(data)
    progress("done", 1.0)
    return Result(data, "image/svg+xml", ".svgz" if options.svgz else ".svg", report)


def convert(path: str | Path, options: ConversionOptions, progress: Progress = no_progress,
            cache: str | Path | None = None, on_prepared: Callable[[FaceAnimation], None] | None = None) -> Result:
    """Convert an input file with the options: the whole pipeline, nothing written to disk."""
    t = time.perf_counter()
    progress("load", 0.0)
    anim = load(path, options, cache, progress)
    load_s = time.perf_counter() - t
    sha = file_sha256(path) if Path(path).is_file() else ""  # an ICT FaceKit folder has no one file to hash
    result = convert_animation(anim, options, progress, source_sha256=sha, on_prepared=on_prepared)
    result.report.timings = {"load": load_s, **result.report.timings}
    return result


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write bytes to path through a temporary file in the same folder and a rename: never half-written."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
