"""What a worker does with one job (both backends): claim it, convert, write results and previews, record."""

from __future__ import annotations

import dataclasses
import gzip
import io
import logging
import os
import tempfile
import time
import traceback

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np
from PIL import Image

from converter import mpeg4
from converter.animation import FaceAnimation
from converter.convert import convert
from converter.errors import FacesvgError
from converter.extract import extract, fit_camera
from converter.isolated import die_with_parent
from converter.options import ConversionOptions, Eta
from converter.outputs import output_kind
from converter.userfiles import write_atomic
from converter.verify import verify_animation
from webapp import strictjson
from webapp.jobstore import CANCELLING, DONE, FAILED, RUNNING, Job, JobStore, is_damaged, open_store
from webapp.lease import Heartbeat, new_owner
from webapp.messages import user_words, with_user_names
from webapp.storage import Storage, result_files

log = logging.getLogger("facesvg.webapp")
PREVIEW_MAX_SIZE = 512  # the 3D prerender is drawn at most this wide (same camera framing, smaller viewport)
CONVERT_SHARE = 0.8  # share of the progress bar given to the conversion; then verification and the prerender
VERIFY_SHARE = 0.05


class JobCancelled(Exception):
    """The job was asked to stop (DELETE while running)."""


class ClaimLost(Exception):
    """This worker no longer holds the job (its lease ran out and someone else settled it)."""


def run_job(job_id: str, store_url: str, storage_root: str, preview_frames: int = 48,
            lease_seconds: float = 60.0) -> str:
    """Claim one queued job and run it to its end state; returns the outcome. Entry point of RQ work horses."""
    die_with_parent(os.getppid())  # an RQ work horse stops with its worker (kill -9 of the worker included)
    store = open_store(store_url)
    owner = new_owner("rq")
    try:
        if not store.claim(job_id, owner, lease_seconds):
            return "skipped"  # cancelled, deleted, or taken by another worker
        return execute(store, Storage(storage_root), job_id, owner, lease_seconds, preview_frames,
                       parent_pid=os.getppid())
    finally:
        store.close()


def execute(store: JobStore, storage: Storage, job_id: str, owner: str, lease_seconds: float,
            preview_frames: int = 48, parent_pid: int | None = None) -> str:
    """Run a job this worker has claimed (as owner), renewing its lease; every write is conditional on owning it."""
    job = store.get(job_id)
    if job is None or job.owner != owner:
        return "lost"
    if is_damaged(job):  # its options cannot be read back: converting with defaults would be a wrong result
        return _fail(store, storage, job_id, owner, job.message)
    with Heartbeat(store, job_id, owner, lease_seconds, parent_pid) as beat:
        progress = ProgressRecorder(store, job_id, owner=owner, lost=beat.lost)
        try:
            result = perform(job, storage, progress, preview_frames)
        except JobCancelled:
            return _cancelled(store, storage, job_id, owner)
        except ClaimLost:
            return _discard(storage, job_id, owner, "claim lost while converting")
        except FacesvgError as exc:
            return _fail(store, storage, job_id, owner, with_user_names(user_words(str(exc)), job.files, job.names))
        except Exception as exc:  # a bug or a resource failure: keep the server alive, tell the user plainly
            log.error("job %s failed:\n%s", job_id, traceback.format_exc())
            return _fail(store, storage, job_id, owner, with_user_names(
                f"the conversion failed unexpectedly ({type(exc).__name__}: {exc}).", job.files, job.names))
        if store.transition(job_id, (RUNNING,), holder=owner, state=DONE, stage="done", progress=1.0,
                            finished=time.time(), result=result, owner="", lease=0.0):
            record_event(storage, job_id, f"done {owner}")
            return DONE
        return _after_lost_transition(store, storage, job_id, owner)


def _fail(store: JobStore, storage: Storage, job_id: str, owner: str, message: str) -> str:
    if store.transition(job_id, (RUNNING,), holder=owner, state=FAILED, stage="failed", message=message,
                        finished=time.time(), owner="", lease=0.0):
        record_event(storage, job_id, f"failed {owner}")
        return FAILED
    return _after_lost_transition(store, storage, job_id, owner)


def _after_lost_transition(store: JobStore, storage: Storage, job_id: str, owner: str) -> str:
    """A final write was refused: either a DELETE asked us to stop (we still own it) or our claim is gone."""
    job = store.get(job_id)
    if job is not None and job.state == CANCELLING and job.owner == owner:
        return _cancelled(store, storage, job_id, owner)
    return _discard(storage, job_id, owner, "claim lost before recording")


def _cancelled(store: JobStore, storage: Storage, job_id: str, owner: str) -> str:
    """DELETE arrived while we ran it: finish that explicit delete (only while we still hold the job)."""
    if store.transition(job_id, (CANCELLING,), holder=owner, state="cancelled", owner="", finished=time.time()):
        store.remove(job_id)
        storage.delete(job_id)
        return "cancelled"
    return _discard(storage, job_id, owner, "claim lost while cancelling")


def _discard(storage: Storage, job_id: str, owner: str, why: str) -> str:
    """Our claim was lost: leave the job to whoever holds it now; touch nothing but the event log."""
    log.warning("job %s: %s (%s); result discarded", job_id, why, owner)
    record_event(storage, job_id, f"discarded {owner}")
    return "lost"


def record_event(storage: Storage, job_id: str, line: str) -> None:
    """Append one line to the job's event log (who finished it; read by the fault tests and operators)."""
    folder = storage.job_dir(job_id)
    if not folder.is_dir():
        return
    with open(folder / "events.log", "a", encoding="utf-8") as fh:
        fh.write(f"{time.time():.3f} {line}\n")


class ProgressRecorder:
    """Progress callback that writes (stage, fraction) to the store at most every 0.2 s and checks for cancel;
    with them, once, where the input had been read (the ETA's origin: options.Eta)."""

    def __init__(self, store: JobStore, job_id: str, interval: float = 0.2, owner: str | None = None,
                 lost=None) -> None:
        self.store, self.job_id, self.interval = store, job_id, interval
        self.owner, self.lost = owner, lost
        self.last = 0.0
        self.eta = Eta()
        self.origin_saved = False

    def __call__(self, stage: str, fraction: float) -> None:
        if self.lost is not None and self.lost.is_set():
            raise ClaimLost()
        origin = self.eta.see(stage, fraction, time.time())
        now = time.monotonic()
        if now - self.last < self.interval and fraction < 1.0:
            return
        self.last = now
        fraction = float(min(max(fraction, 0.0), 1.0))
        extra = {}
        if not self.eta.loading and not self.origin_saved:
            extra["progress_origin"] = {"time": origin[0], "progress": round(origin[1], 4)}
            self.origin_saved = True
        if not self.store.transition(self.job_id, (RUNNING,), holder=self.owner, stage=stage,
                                     progress=round(fraction, 4), **extra):
            job = self.store.get(self.job_id)
            if job is None:
                raise JobCancelled()
            if self.owner is not None and job.owner != self.owner:
                raise ClaimLost()
            if job.state == CANCELLING:
                raise JobCancelled()


def job_options(job: Job, storage: Storage):
    """ConversionOptions of a job: its scalar options plus the stored extra files as paths."""
    data = dict(job.options)
    inputs = storage.inputs(job.id)
    for role, name in job.files.items():
        if role not in ("input", "cache"):
            data[role] = str(inputs / name)
    return ConversionOptions.from_mapping(data)


def perform(job: Job, storage: Storage, progress, preview_frames: int = 48) -> dict:
    """Convert the job's input, write every output and the 3D prerenders; returns the result summary."""
    options = job_options(job, storage)
    inputs = storage.inputs(job.id)
    cache = inputs / job.files["cache"] if "cache" in job.files else None
    # The 3D frames are set aside in an anonymous file (gone with it, or with the process) while the writer runs,
    # then mapped back for the verifier and the prerender: held, they added to the writer's peak (a long capture's
    # are large: bench_webjob). Written with tofile, not through a mapping, so they leave this process's memory.
    with tempfile.TemporaryFile(dir=storage.job_dir(job.id), prefix=".frames-") as aside:
        rest: dict = {}

        def set_aside(anim: FaceAnimation) -> None:
            anim.frames.tofile(aside)
            aside.flush()
            rest.update(shape=anim.frames.shape,
                        fields={f.name: getattr(anim, f.name) for f in dataclasses.fields(anim) if f.name != "frames"})

        result = convert(inputs / job.files["input"], options,
                         progress=lambda s, f: progress(s, CONVERT_SHARE * f), cache=cache, on_prepared=set_aside)
        anim = FaceAnimation(np.memmap(aside, np.float32, "r", shape=rest["shape"]), **rest["fields"])
        return _finish(job, storage, progress, preview_frames, options, result, anim)


def _finish(job: Job, storage: Storage, progress, preview_frames: int, options: ConversionOptions, result,
            anim: FaceAnimation) -> dict:
    """perform's outputs after the conversion: every output file, the verifier's figures, the 3D prerenders."""
    kind = output_kind(options.to)
    out = storage.out(job.id)
    if kind.takes_fap_stream:  # e.g. the fap2d package plays the stream: prerender the 3D face it drives
        anim = mpeg4.drive(anim, options.fap, options.fdp, fps=options.fps)
    # Every file of the kind: the main one and its variants (the SVG and its gzip).
    main = gzip.decompress(result.data) if kind.file_for(options).gzip else result.data
    outputs: dict[str, bytes] = {f.key: gzip.compress(main, mtime=0) if f.gzip else main for f in kind.files}
    report = result.report.to_json()
    if kind.verify:
        progress("verify", CONVERT_SHARE)
        report["figures"].update(fidelity(main, anim))
        if report["figures"].get("budget_within_bound") is False and "within_tolerance" in report["figures"]:
            report["figures"]["within_tolerance"] = False  # the triangle budget moved the face past its bound
    report = strictjson.finite(report)  # a figure that could not be measured (NaN) is stored, and served, as null
    outputs["report"] = strictjson.dumps(report, indent=1, sort_keys=True).encode()
    files = result_files()
    for key, data in outputs.items():
        write_atomic(out / files[key][0], data)
    progress("prerender", CONVERT_SHARE + VERIFY_SHARE)
    still = options.frame is not None and kind.stills
    frames = write_previews(anim, options, out, preview_frames, progress, only=options.frame if still else None)
    progress("done", 1.0)
    return {
        "report": report,
        "frames": int(anim.n_frames),
        "fps": float(anim.fps),
        "duration": float(anim.n_frames / anim.fps),
        "size": int(options.size),
        "preview_frames": frames,
        "still": options.frame if still else None,  # the SVG shows this one frame, not the animation
        "outputs": {k: len(v) for k, v in outputs.items()},
        "media_type": result.media_type,
        # a face with morph targets and no take to drive them: the page says a take can (its one frame is a still)
        "morph_targets": morph_count(anim.extras.get("morph_targets")),
    }


def morph_count(value) -> int:
    """How many morph targets a loader reported: a list of their names or a count (loaders say either)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return int(value)
    try:
        return len(value)
    except TypeError:
        return 0


def fidelity(svg: bytes, anim) -> dict:
    """The verifier's figures for the SVG against the exact projection (empty if it cannot measure this SVG)."""
    try:
        v = verify_animation(svg, anim)
    except Exception as exc:  # an optional measurement: a verifier limit must not fail the user's job
        log.warning("verification skipped: %s: %s", type(exc).__name__, exc)
        return {}
    return {"max_deviation_px": float(v.max_px), "mean_deviation_px": float(v.mean_px),
            "visibility_mismatches": int(v.visibility_mismatches), "tolerance_px": float(v.tolerance),
            "within_tolerance": bool(v.ok)}


def preview_indices(n_frames: int, limit: int) -> list[int]:
    """At most limit frame indices spread evenly over the animation, always including the first and last."""
    if n_frames <= limit:
        return list(range(n_frames))
    return sorted(set(np.round(np.linspace(0, n_frames - 1, max(limit, 2))).astype(int).tolist()))


def write_previews(anim, options, out, limit: int, progress, only: int | None = None) -> list[int]:
    """The 3D prerender (pyrender, same camera framing as the 2D output) of chosen frames (or one) as PNGs."""
    frames = preview_indices(anim.n_frames, limit) if only is None else [only]
    if not frames:
        return []
    camera = fit_camera(anim, min(options.size, PREVIEW_MAX_SIZE), options.yaw, options.pitch, options.fov,
                        options.ortho, options.frame_on)
    sheet = extract(anim, camera, neutral=0, occlusion=False, reference_frames=tuple(frames))
    for i, k in enumerate(frames):
        buf = io.BytesIO()
        Image.fromarray(sheet.references[k]).save(buf, format="PNG", optimize=False)
        write_atomic(out / f"preview-{k}.png", buf.getvalue())
        done = CONVERT_SHARE + VERIFY_SHARE
        progress("prerender", done + (1 - done) * (i + 1) / len(frames))
    return frames
