"""HTML pages: upload form, live job page / result player, recent jobs."""

from __future__ import annotations

import logging
import math
from datetime import UTC, datetime
from urllib.parse import quote

from flask import Blueprint, abort, current_app, flash, g, redirect, render_template, request, url_for

from converter.errors import InputError
from converter.formats import captures
from converter.options import option_fields
from converter.outputs import OUTPUTS, choices, output_files
from converter.playcost import playback_class
from webapp.eta import standing
from webapp.jobstore import DONE, damaged
from webapp.limits import size_text, upload_limit
from webapp.messages import user_words
from webapp.openapi import openapi_document
from webapp.presets import PRESETS, estimate_sizes, has_preset
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
        widget = "file" if meta.path else "select" if offered else "check" if spec.type is bool else \
            "text" if spec.type is str else "number"
        out.append({"name": spec.name, "label": meta.label or spec.name, "widget": widget, "value": spec.default,
                    "choices": dict(offered or {}), "min": meta.minimum, "max": meta.maximum,
                    "step": 1 if spec.type is int else "any", "placeholder": meta.unset,
                    "hint": WEB_HINTS.get(spec.name, meta.help),
                    "accept": file_accept(spec.name, meta.accept), "advanced": meta.advanced})
    return out


# Hints in the form's words where the option's help speaks of the command line.
WEB_HINTS = {
    "animation": "a clip's name or number, or all (every clip together); the face you choose lists its clips here",
    "frame_on": "frame only this part or glTF node or mesh; the face you choose lists its parts and nodes here",
    "weights": "a take from a face-capture app that drives the face's named morph targets",
}
# Where a text option's suggestions come from in /api/v1/inspect's answer (the upload form's datalists).
SUGGESTIONS = {"animation": "animations", "frame_on": "frame_on"}
# Output files without a browser view of their own, shown in a page of static/ that plays them.
VIEWER_PAGES = {"fap2d": "fap2d.html"}
# The result page's words for the report's figures: label, unit (a figure not listed reads as its key in words).
FIGURES = {
    "playback_ms_4x": ("Playback cost on a slow phone", "ms a frame"),
    "keys_per_path": ("Keyframes per animated shape", ""),
    "color_error_max_levels": ("Largest colour error", "levels of 255"),
    "color_error_p99_levels": ("Colour error of 99 % of shapes, at most", "levels of 255"),
    "budget_deviation_px": ("Largest shape change from the triangle budget", "px"),
    "budget_deviation_mean_px": ("Mean shape change from the triangle budget", "px"),
    "budget_bound_px": ("Largest shape change the triangle budget may make", "px"),
    "budget_bound_mean_px": ("Mean shape change the triangle budget may make", "px"),
    "budget_within_bound": ("Triangle budget within its bound, no visible part lost", ""),
    "max_deviation_px": ("Largest drawing error, measured", "px"),
    "mean_deviation_px": ("Mean drawing error, measured", "px"),
    "tolerance_px": ("Drawing error allowed", "px"),
    "within_tolerance": ("Drawing error within the allowed", ""),
    "visibility_mismatches": ("Triangles shown or hidden wrongly", ""),
}
KEPT = "budget_coverage_kept_"  # + a part's label: the share of its frame-0 pixels the triangle budget kept


def figure_rows(figures: dict) -> list[tuple[str, str, str]]:
    """(key, label, value with its unit) of each report figure, in the user's words, in FIGURES' order."""
    rows = []
    order = {k: i for i, k in enumerate(FIGURES)}
    for key in sorted(figures, key=lambda k: (order.get(k, len(order)), k)):
        value = figures[key]
        if key.startswith("budget_deviation_px_"):  # one per part: "… from the triangle budget (skin)"
            label, unit = f"{FIGURES['budget_deviation_px'][0]} ({key.rsplit('_', 1)[-1]})", "px"
        elif key.startswith(KEPT) and isinstance(value, (int, float)) and not isinstance(value, bool):
            label = f"Pixels of {key.removeprefix(KEPT)} still shown after the triangle budget"
            rows.append((key, label, f"{num(100 * value, '.3g')} %"))
            continue
        else:
            known = FIGURES.get(key)
            bare, unit = (key[:-3], "px") if key.endswith("_px") else (key, "")
            label, unit = known or (bare.replace("_", " ").capitalize(), unit)
        text = ("yes" if value else "no") if isinstance(value, bool) else num(value, ".3g") \
            if isinstance(value, float) else num(value)
        rows.append((key, label, f"{text} {unit}" if unit and text != "—" else text))
    return rows


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
    take = next((c for c in controls if c["name"] == "weights"), None)
    return render_template("upload.html", fields=controls, refill=refill or {}, accept=ACCEPT,
                           cache_accept=CACHE_ACCEPT, error=error, presets=PRESETS, recent=_visible(8),
                           max_bytes=limit, max_text=size_text(limit), take=take, layouts=captures.labels(),
                           suggestions=SUGGESTIONS), status


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
    return render_template("api.html", doc=openapi_document(), outputs=OUTPUTS.values())


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
    result = job.result or {}
    report = result.get("report") or {}
    frames = result.get("frames")
    still = job.state == DONE and (result.get("still") is not None or frames == 1)
    return render_template("job.html", job=job, kinds=kinds, labels=labels, standing=standing(queue(), job),
                           error=user_words(job.message) if job.message else "",
                           estimates=estimate_sizes(job) if job.state == DONE else [], playback=_playback(job),
                           viewer=viewer(job, kinds) if job.state == DONE else None, still=still,
                           undriven=still and not job.files.get("weights") and bool(result.get("morph_targets")),
                           layouts=captures.labels(), figure_rows=figure_rows(report.get("figures") or {}),
                           warnings=[user_words(w) for w in report.get("warnings") or []],
                           is_mobile=has_preset(job, "mobile") if "mobile" in PRESETS else False,
                           kind_label=_kind_label(job),
                           option_labels={spec.name: spec.meta.label or spec.name for spec in option_fields()})


def _kind_label(job) -> str:
    """The job's output kind as the form names it."""
    kind = OUTPUTS.get((job.options or {}).get("to", "svg"))
    return kind.label if kind else str((job.options or {}).get("to", ""))


def viewer(job, kinds: list[str]) -> dict | None:
    """How the result page shows a finished job's main output, for any registered kind: an SVG inline ("svg"),
    an HTML page or a static viewer page in a frame with the output's own controls ("frame"), or None."""
    kind = OUTPUTS.get((job.options or {}).get("to", "svg"))
    if kind is None:
        return None
    main = kind.files[0]
    if main.key not in kinds:
        return None
    src = url_for("api.get_result_kind", job_id=job.id, kind=main.key)
    if main.media_type == "image/svg+xml" and not main.gzip:
        return {"type": "svg", "src": src, "label": kind.label}
    if main.media_type == "text/html":
        return {"type": "frame", "src": src, "label": kind.label}
    if main.key in VIEWER_PAGES:
        page = url_for("static", filename=VIEWER_PAGES[main.key])
        return {"type": "frame", "src": f"{page}?src={quote(src, safe='')}", "label": kind.label}
    return None


def _playback(job) -> str:
    """The predicted playback of a finished flat SVG job in words ('' when its report has no prediction)."""
    figures = ((job.result or {}).get("report") or {}).get("figures") or {}
    ms = figures.get("playback_ms_4x")
    if not isinstance(ms, (int, float)) or not math.isfinite(ms):
        return ""
    return f"{playback_class(ms)} ({num(float(ms), '.3g')} ms a frame on a slow phone)"


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
