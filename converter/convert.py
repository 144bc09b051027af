"""The one path through facesvg: load -> 3D stages -> 2D stage -> writer, with a Report; nothing written to disk."""

from __future__ import annotations

import gzip
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from converter import cloning, formats, framing, heap, mpeg4, puppet, simplify, smoothing
from converter import extract as extraction
from converter.animation import FaceAnimation
from converter.blendshapes import drive_file
from converter.encode.parallel import serial_blas
from converter.errors import InputError
from converter.mpeg4 import fat2d
from converter.options import ConversionOptions, Progress, Report, no_progress, span
from converter.outputs import FAT2D, PUPPET, SHEET, OutputKind, output_kind
from converter.sheet import Sheet
from converter.userfiles import file_sha256

WRITE_FROM = 0.2  # where the writer's share of a job's progress starts: the flat SVG's writer takes most of the
# time after loading (on the capture-like face, 8k x 1,000 and the ICT head x 1,000 alike), so the ETA extrapolated
# from the fraction done holds (bench_progress)
LOADED_AT = 0.05  # where reading the input ends (a guess: options.Eta extrapolates from there)
PREPARED_AT = 0.1  # where the 3D stages end (loading 0.05, FAP driving, cloning) and the 2D stage starts...
SIMPLIFY_FROM = 0.08  # ... unless a triangle budget simplifies the mesh: it starts here and takes its share
BUDGET_COST = 0.04  # its time per original triangle-frame (its passes over every frame) against the rest's per
# budget triangle-frame (extraction and the flat writer), as timed on the ICT head x 4,000 frames to 1,500 triangles


@dataclass
class Result:
    """A finished conversion: the output bytes, its media type and extension, and the Report."""

    data: bytes
    media_type: str
    extension: str
    report: Report


def load(path: str | Path, options: ConversionOptions, cache: str | Path | None = None,
         progress: Progress = no_progress) -> FaceAnimation:
    """Read the input file named by path (plus an optional point cache) with the options' fps and animation."""
    if output_kind(options.to).stage == PUPPET:  # the face itself and the capture to embed: the stage reads both
        return puppet.load(path, options, progress=lambda s, f: progress(s, LOADED_AT * f))
    if options.weights:  # the input is a face with named morph targets, animated by the capture
        return drive_file(path, options.weights, fps=options.fps, progress=lambda s, f: progress(s, LOADED_AT * f))
    return formats.load(path, fps=options.fps, cache=cache, animation=options.animation)


def prepared_at(anim: FaceAnimation, options: ConversionOptions) -> float:
    """Where on a conversion's progress its 3D stages end: PREPARED_AT, later when a triangle budget simplifies
    the mesh (the frame count cancels out; a clone target's triangles are not known before it loads)."""
    if options.max_triangles is None or options.max_triangles >= anim.n_faces:
        return PREPARED_AT
    budget = BUDGET_COST * anim.n_faces
    return max(PREPARED_AT, SIMPLIFY_FROM + (1 - SIMPLIFY_FROM) * budget / (budget + options.max_triangles))


def prepare(
    anim: FaceAnimation, options: ConversionOptions, report: Report, progress: Progress = no_progress
) -> FaceAnimation:
    """The optional 3D stages in order: FAP driving, frame range, cloning, triangle budget (progress up to
    prepared_at)."""
    ready = prepared_at(anim, options)
    anim = framing.decide(anim, options.frame_on)  # before the stages, which may drop the vertices it looks at
    if "weights" in anim.extras:  # what the weight capture matched, from load()
        report.counts.update(anim.extras["weights"]["counts"])
        report.warnings.extend(anim.extras["weights"]["warnings"])
    if options.fap and not output_kind(options.to).takes_fap_stream:  # e.g. the fap2d package carries the stream
        t = time.perf_counter()
        anim = mpeg4.drive(anim, options.fap, options.fdp, fps=options.fps)
        report.timings["fap"] = time.perf_counter() - t
        progress("fap", 0.05)
    if options.start or options.end is not None:
        anim = anim.sliced(options.start, options.end)
    if options.clone_target:
        t = time.perf_counter()
        target = formats.load(options.clone_target)
        anim = cloning.clone(anim, target, options.clone_method, keys=options.clone_keys,
                             correspondences=options.correspondences)
        report.timings["clone"] = time.perf_counter() - t
        progress("clone", 0.08)
    if options.max_triangles is not None and options.max_triangles < anim.n_faces:
        t = time.perf_counter()
        anim = simplify.simplify(anim, options.max_triangles, report, options=options,
                                 progress=span(progress, SIMPLIFY_FROM, ready, stage="simplify"))
        report.timings["simplify"] = time.perf_counter() - t
        progress("simplify", ready)
    if options.smooth:
        anim = smoothing.apply(anim, options, report)
    return anim


def extract_sheet(anim: FaceAnimation, options: ConversionOptions, report: Report,
                  progress: Progress = no_progress) -> Sheet:
    """The SHEET stage: camera framing plus converter.extract, checked to show at least one triangle."""
    if options.frame is not None and not 0 <= options.frame < anim.n_frames:
        raise InputError(f"--frame {options.frame} is outside 0..{anim.n_frames - 1}; choose a frame inside it.")
    t = time.perf_counter()
    camera = extraction.fit_camera(anim, options.size, options.yaw, options.pitch, options.fov, options.ortho,
                                   options.frame_on)
    report.warnings.extend(framing.resolve(anim, options.frame_on).notes)  # what was framed, and why
    sheet = extraction.extract(
        anim, camera, neutral=options.neutral_frame, occlusion=options.occlusion, progress=progress,
        occlusion_frames=None if options.frame is None else (options.frame,),  # a still: only its frame counts
        vertex_colors=options.shading != "flat",  # only Gouraud outputs read them
    )
    if not sheet.kept.any():
        raise InputError("no triangle is ever visible from this camera (all face away or lie outside the view); "
                         "check --yaw/--pitch or the mesh's winding.")
    sheet.info["source_frames"] = [options.start, options.start + anim.n_frames]
    heap.give_back()  # extraction's temporaries, before the writer's
    report.timings["extract"] = time.perf_counter() - t
    report.counts.update({k: v for k, v in sheet.info.items() if isinstance(v, int)})
    return sheet


STAGES: dict[str, Callable[[FaceAnimation, ConversionOptions, Report, Progress], Any]] = {
    SHEET: extract_sheet,
    FAT2D: fat2d.stage,
    PUPPET: puppet.stage,
}
"""The 2D stage of each OutputKind.stage: prepared FaceAnimation -> what the kind's writer reads."""


def convert_animation(
    anim: FaceAnimation, options: ConversionOptions, progress: Progress = no_progress, source_sha256: str = "",
    on_prepared: Callable[[FaceAnimation], None] | None = None,
) -> Result:
    """Convert an in-memory FaceAnimation with the options; the library's main entry point.

    Its 3D frames are let go once the 2D stage has read them: a caller that keeps no reference of its own (as
    ``convert`` does) has them freed before the writer, whose peak they would otherwise add to (a long capture's
    are large: BENCHMARKS.md, conversion speed and memory)."""
    kind: OutputKind = output_kind(options.to)
    report = Report()
    report.warnings.extend(anim.extras.get("warnings", ()))  # the loader's notes (e.g. glTF clips not played)
    ready = prepared_at(anim, options)
    anim = prepare(anim, options, report, progress)
    rest = span(progress, ready, 1.0)  # the 2D stage and the writer keep their shares of what is left
    write_from = (WRITE_FROM - PREPARED_AT) / (1 - PREPARED_AT)
    if on_prepared is not None:  # callers that also need the 3D animation (the web UI's prerender)
        on_prepared(anim)
    with serial_blas():
        data2d = STAGES[kind.stage](anim, options, report, span(rest, 0.0, write_from))
        del anim  # nothing after the 2D stage reads the 3D animation
        if isinstance(data2d, Sheet):  # the SVG metadata names its source file
            data2d.info["source_sha256"] = source_sha256
        write = kind.writer_for(options)
        t = time.perf_counter()
        rest("write", write_from)
        data = write(data2d, options, report, span(rest, write_from, 1.0))
    report.sizes[kind.name] = len(data)
    out = kind.file_for(options)
    if out.gzip:
        data = gzip.compress(data, mtime=0)
    report.timings["write"] = time.perf_counter() - t
    report.sizes["output"] = len(data)
    progress("done", 1.0)
    return Result(data, out.media_type, out.extension, report)


def convert(path: str | Path, options: ConversionOptions, progress: Progress = no_progress,
            cache: str | Path | None = None, on_prepared: Callable[[FaceAnimation], None] | None = None) -> Result:
    """Convert an input file with the options: the whole pipeline, nothing written to disk."""
    t = time.perf_counter()
    progress("load", 0.0)
    anim = load(path, options, cache, progress)
    load_s = time.perf_counter() - t
    progress("loaded", LOADED_AT)
    sha = file_sha256(path) if Path(path).is_file() else ""  # an ICT FaceKit folder has no one file to hash
    handed = [anim]  # handed over: no name here keeps it, so its frames go before the writer runs
    del anim
    result = convert_animation(handed.pop(), options, progress, source_sha256=sha, on_prepared=on_prepared)
    result.report.timings = {"load": load_s, **result.report.timings}
    return result
