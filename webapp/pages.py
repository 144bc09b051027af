"""HTML pages: upload form, live job page / result player, recent jobs."""

from __future__ import annotations

import logging
import math
from datetime import UTC, datetime

from flask import Blueprint, abort, current_app, flash, g, redirect, render_template, request, url_for

from converter.errors import InputError
from converter.formats import captures
from converter.options import option_fields
from converter.outputs import choices, output_files
from converter.playcost import playback_class
from webapp.eta import standing
from webapp.jobstore import DONE, damaged
from webapp.limits import size_text, upload_limit
from webapp.messages import user_words
from webapp.openapi import openapi_document
from webapp.presets import PRESETS, estimate_sizes
from webapp.security import may_see
from webapp.storage import is_job_id
from webapp.submit import OPTION_FIELDS, create_job

pages = Blueprint("pages", __name__)
log = logging.getLogger("facesvg.webapp")

# Every face file converter.formats loads (recognised by content; these are their usual names): glTF and GLB (a
# VRM avatar is a GLB), a zip of OBJ/PLY frames or of a mesh and its point cache, an OBJ or PLY mesh.
FACE_SUFFIXES = (".glb", ".gltf", ".vrm", ".zip", ".obj", ".ply")
ACCEPT = ",".join((*FACE_SUFFIXES, "model/gltf-binary", "model/gltf+json", "application/zip"))
CACHE_ACCEPT = ".pc2,.mdd,.npy"  # the point caches converter.formats.pointcache reads
FACE_FIELDS = ("clone_target",)  # path options that take a face like the main input (checked as one)
CAPTURE_ACCEPT = ",".join(captures.extensions())  # every capture layout's usual suffixes


def queue():
    """The app's job queue."""
    return current_app.extensions["facesvg_queue"]


@pages.app_template_filter("when")
def when(ts: float | None) -> str:
    """A UTC timestamp for display."""
    if not ts:
        return "—"
    return datetime.fromtimestamp(ts, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


@pages.app_template_filter("kb")
def kb(n: int | None) -> str:
    """Bytes as KB/MB text."""
    if not isinstance(n, (int, float)) or isinstance(n, bool) or not math.isfinite(n):
        return "—"
    return f"{n / 1024:.1f} KB" if n < 1 << 20 else f"{n / (1 << 20):.2f} MB"


@pages.app_template_filter("num")
def num(value: object, spec: str = "") -> str:
    """A figure for display: whole numbers bare, others to 4 significant digits or spec; missing or NaN: a dash."""
    if value is None or isinstance(value, bool):
        return "—" if value is None else str(value)
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            return "—"
        if spec:
            return format(value, spec)
        if isinstance(value, float):
            return f"{value:.0f}" if value.is_integer() else f"{value:.4g}"
    return str(value)


def form_fields() -> list[dict]:
    """The upload form's option controls, from the ConversionOptions metadata and the output registry."""
    out = []
    for spec in option_fields():
        meta = spec.meta
        if not meta.form:
            continue
        offered = choices(spec)
        widget = "file" if meta.path else "select" if offered else "check" if spec.type is bool else "number"
        out.append({"name": spec.name, "label": meta.label or spec.name, "widget": widget, "value": spec.default,
                    "choices": dict(offered or {}), "min": meta.minimum, "max": meta.maximum,
                    "step": 1 if spec.type is int else "any", "placeholder": meta.unset, "hint": meta.help,
                    "accept": file_accept(spec.name, meta.accept), "advanced": meta.advanced})
    return out


def file_accept(name: str, declared: str) -> str:
    """An extra file input's accept list: a face's like the main input, the capture registry's, else declared."""
    if name in FACE_FIELDS:
        return ACCEPT
    if name == "weights":
        return CAPTURE_ACCEPT
    return declared


@pages.app_template_filter("duration")
def duration(seconds: float | None) -> str:
    """An estimate in words: 'about 40 s', 'about 3 min'."""
    if seconds is None:
        return "—"
    if seconds < 90:
        return f"about {max(int(round(seconds)), 1)} s"
    return f"about {int(round(seconds / 60))} min"


def _defaults() -> dict:
    return {spec.name: spec.default for spec in option_fields()}


def _form(status: int = 200, error: str | None = None, refill: dict | None = None):
    """The upload page, its fields filled from refill (a failed job's options or the form just sent)."""
    controls = form_fields()
    for control in controls:
        if refill and control["name"] in refill and control["widget"] != "file":
            control["value"] = refill[control["name"]]
    limit = upload_limit(current_app.config)
    return render_template("upload.html", fields=controls, refill=refill or {}, accept=ACCEPT,
                           cache_accept=CACHE_ACCEPT, error=error, presets=PRESETS, recent=_visible(8),
                           max_bytes=limit, max_text=size_text(limit)), status


def _visible(limit: int) -> list:
    """Recent jobs this browser may see (all when API keys are off)."""
    if not getattr(g, "client", ""):
        return queue().recent(limit)
    return [j for j in queue().recent(max(limit * 20, 500)) if may_see(j)][:limit]


def _sent_options() -> dict:
    """The scalar options of the form just submitted, as typed (to show them again with an error)."""
    out = {}
    for key in request.form.keys():
        name = key.replace("-", "_")
        if name in OPTION_FIELDS:
            value = request.form.getlist(key)[-1]
            out[name] = {"0": False, "1": True}.get(value, value) if value in ("0", "1") and \
                isinstance(_defaults().get(name), bool) else value
    return out


@pages.get("/")
def index():
    """The upload page; ?retry=JOB refills the form with that job's options ("Try again")."""
    refill = None
    retry = request.args.get("retry", "")
    if is_job_id(retry):
        job = queue().get(retry)
        if job is not None and may_see(job):
            refill = {k: v for k, v in job.options.items() if k in OPTION_FIELDS}
    preset = PRESETS.get(request.args.get("preset", ""))
    if preset:
        refill = {**(refill or {}), **preset[1]}
    return _form(refill=refill)


@pages.post("/jobs")
def submit():
    """Form submission: queue the job and go to its page (303), or show the form again with the error."""
    current_app.extensions["facesvg_cleanup"].maybe_run()
    try:
        job = create_job(queue(), current_app.config, request.form, request.files, client=getattr(g, "client", ""))
    except InputError as exc:
        return _form(400, error=user_words(str(exc)), refill=_sent_options())
    return redirect(url_for("pages.job_page", job_id=job.id), code=303)


@pages.get("/docs/api")
def api_docs():
    """The OpenAPI document of /api/v1 as a readable page."""
    return render_template("api.html", doc=openapi_document())


@pages.get("/jobs")
def jobs():
    """Recent jobs."""
    return render_template("jobs.html", jobs=_visible(100))


@pages.get("/jobs/<job_id>")
def job_page(job_id: str):
    """Progress while queued/running, the error when failed, the result player when done."""
    job = queue().get(job_id) if is_job_id(job_id) else None
    if job is None or not may_see(job):
        abort(404, description="There is no such job; it may have been deleted or cleaned up.")
    try:
        return _job_page(job)
    except Exception as exc:  # a stored result the page cannot show: show the job as damaged, not a 500
        log.warning("job %s: cannot show its page: %r", job.id, exc)
        return _job_page(damaged(job, "its result could not be read"))


def _job_page(job) -> str:
    kinds = queue().storage.available(job.id) if job.state == DONE else []
    labels = {**{key: f.label for key, f in output_files().items()}, "report": "Report (JSON)"}
    return render_template("job.html", job=job, kinds=kinds, labels=labels, standing=standing(queue(), job),
                           error=user_words(job.message) if job.message else "",
                           estimates=estimate_sizes(job) if job.state == DONE else [], playback=_playback(job))


def _playback(job) -> str:
    """The playback class of a finished flat SVG job ('' when its report has no prediction)."""
    figures = ((job.result or {}).get("report") or {}).get("figures") or {}
    ms = figures.get("playback_ms_4x")
    return playback_class(ms) if isinstance(ms, (int, float)) and math.isfinite(ms) else ""


@pages.post("/jobs/<job_id>/delete")
def delete(job_id: str):
    """Delete (or cancel) a job from its page."""
    job = queue().get(job_id) if is_job_id(job_id) else None
    if job is None or not may_see(job):
        abort(404, description="There is no such job.")
    outcome = queue().delete(job_id)
    if outcome is None:
        abort(404, description="There is no such job.")
    flash("The job is stopping; it will be removed shortly." if outcome == "cancelling" else "Job deleted.")
    return redirect(url_for("pages.jobs"), code=303)
