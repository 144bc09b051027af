"""The puppet's 2D stage: a face with named morph targets -> Puppet (2D mesh, colours, per-parameter 2D FAT tables).

`load` reads the face (and the capture to embed, if any) for `--to puppet`: the face itself, not a driven
animation, is what the stage reads. `stage` frames it with the options' camera (extract.fit_camera on the rest
pose, as the other outputs frame their frames) and builds the tables (model.build).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from converter import extract as extraction
from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.morphs import MorphFace, load_morph_face
from converter.formats.weights import read_weights
from converter.options import ConversionOptions, Progress, Report, no_progress
from converter.puppet.model import Parameter, Puppet, Table, Take, build, pose, resolve, shade
from converter.puppet.take import from_track

__all__ = ["Parameter", "Puppet", "Table", "Take", "build", "from_track", "load", "pose", "puppet_of", "resolve",
           "shade",
           "stage"]

FACE_KEY = "puppet_face"  # FaceAnimation.extras: the MorphFace the stage builds from
TAKE_KEY = "puppet_take"  # ... and the capture (WeightTrack) to embed
DEFAULT_FPS = 30.0


def load(path: str | Path, options: ConversionOptions, progress: Progress = no_progress) -> FaceAnimation:
    """The face's rest pose as a one-frame FaceAnimation carrying the MorphFace and the capture for the stage."""
    face = load_morph_face(path, progress)
    if not face.names:
        raise InputError(f"{Path(path).name} has no named morph targets; --to puppet needs a face with them (glTF "
                         "targetNames, an OBJ shape zip or an ICT FaceKit folder).")
    anim = face.still(options.fps or DEFAULT_FPS)
    anim.extras[FACE_KEY] = face
    if options.weights:
        anim.extras[TAKE_KEY] = read_weights(options.weights)
    anim.extras.setdefault("source_path", str(path))
    return anim


def puppet_of(face: MorphFace, options: ConversionOptions, progress: Progress = no_progress) -> Puppet:
    """The puppet of a face with the options' camera and shading (no take)."""
    camera = extraction.fit_camera(face.still(DEFAULT_FPS), options.size, options.yaw, options.pitch, options.fov,
                                   options.ortho, options.frame_on)
    return build(face, camera, gouraud=options.shading != "flat", progress=progress)


def stage(anim: FaceAnimation, options: ConversionOptions, report: Report, progress: Progress = no_progress) -> Puppet:
    """The PUPPET stage: the Puppet of the face `load` read, with the capture embedded when one was given."""
    face = anim.extras.get(FACE_KEY)
    if not isinstance(face, MorphFace):
        raise InputError("--to puppet needs a face with named morph targets read by facesvg convert (glTF "
                         "targetNames, an OBJ shape zip or an ICT FaceKit folder).")
    if anim.n_vertices != len(face.base) or anim.n_faces != len(face.faces):
        raise InputError("--to puppet builds from the face as it is: drop --max-triangles and --clone-target.")
    t = time.perf_counter()
    puppet = puppet_of(face, options, progress)
    report.timings["puppet"] = time.perf_counter() - t
    track = anim.extras.get(TAKE_KEY)
    if track is not None:
        take = from_track(track)
        mapping = resolve(puppet, take.names)
        unmatched = [n for n, row in zip(take.names, mapping) if not row.any()]
        if not mapping.any():
            raise InputError(f"none of the capture's {len(take.names)} weights ({', '.join(take.names[:3])}, ...) "
                             f"names a morph target of the face ({', '.join(face.names[:3])}, ...); rename the "
                             "targets to ARKit names.")
        if unmatched:
            report.warnings.append(f"{len(unmatched)} capture weights found no morph target: {', '.join(unmatched)}.")
        puppet = puppet.with_take(take)
        report.counts.update({"take_frames": take.n_frames, "take_weights": len(take.names),
                              "take_weights_matched": int(len(take.names) - len(unmatched))})
    report.counts.update({"triangles": puppet.source_triangles, "triangles_kept": int(len(puppet.triangles)),
                          "vertices_2d": int(len(puppet.xy)), "parameters": len(puppet.morphs),
                          "morph_intervals": int(puppet.info["morph_intervals"]),
                          "moved_entries": int(sum(len(p.table.vertices) for p in puppet.morphs)),
                          "eyes": len(puppet.eyes)})
    report.counts["frames"] = int(np.int64(puppet.take.n_frames if puppet.take else 1))
    return puppet
