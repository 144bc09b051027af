"""HTML pages: upload form, live job page / result player, recent jobs."""

from __future__ import annotations

from datetime import datetime, timezone

from flask import Blueprint, abort, current_app, flash, redirect, render_template, request, url_for

from converter.errors import InputError
from converter.options import option_fields
from converter.outputs import choices, output_files
from webapp.jobstore import DONE
from webapp.storage import is_job_id
from webapp.submit import create_job

pages = Blueprint("pages", __name__)

ACCEPT = ".glb,.gltf,.zip,.obj,model/gltf-binary,model/gltf+json,application/zip"


def queue():
    """The app's job queue."""
    return current_app.extensions["facesvg_queue"]


@pages.app_template_filter("when")
def when(ts: float | None) -> str:
    """A UTC timestamp for display."""
    if not ts:
        return "—"
    return datetime.fromtimestamp(ts, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


@pages.app_template_filter("kb")
def kb(n: int | None) -> str:
    """Bytes as KB/MB text."""
    if n is None:
        return "—"
    return f"{n / 1024:.1f} KB" if n < 1 << 20 else f"{n / (1 << 20):.2f} MB"


@pages.app_template_filter("num")
def num(value) -> str:
    """A report figure for display: whole numbers without decimals, others to 4 significant digits."""
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
                    "accept": meta.accept, "advanced": meta.advanced})
    return out


@pages.get("/")
def index():
    """The upload page."""
    return render_template("upload.html", fields=form_fields(), accept=ACCEPT,
                           recent=queue().recent(8),
                           max_mb=current_app.config["MAX_CONTENT_LENGTH"] // (1 << 20))


@pages.post("/jobs")
def submit():
    """Form submission: queue the job and go to its page (303), or show the form again with the error."""
    current_app.extensions["facesvg_cleanup"].maybe_run()
    try:
        job = create_job(queue(), current_app.config, request.form, request.files)
    except InputError as exc:
        return render_template("upload.html", fields=form_fields(), accept=ACCEPT, error=str(exc),
                               recent=queue().recent(8),
                               max_mb=current_app.config["MAX_CONTENT_LENGTH"] // (1 << 20)), 400
    return redirect(url_for("pages.job_page", job_id=job.id), code=303)


@pages.get("/jobs")
def jobs():
    """Recent jobs."""
    return render_template("jobs.html", jobs=queue().recent(100))


@pages.get("/jobs/<job_id>")
def job_page(job_id: str):
    """Progress while queued/running, the error when failed, the result player when done."""
    job = queue().get(job_id) if is_job_id(job_id) else None
    if job is None:
        abort(404, description="There is no such job; it may have been deleted or cleaned up.")
    kinds = queue().storage.available(job.id) if job.state == DONE else []
    labels = {**{key: f.label for key, f in output_files().items()}, "report": "Report (JSON)"}
    return render_template("job.html", job=job, kinds=kinds, labels=labels)


@pages.post("/jobs/<job_id>/delete")
def delete(job_id: str):
    """Delete (or cancel) a job from its page."""
    if not is_job_id(job_id):
        abort(404)
    outcome = queue().delete(job_id)
    if outcome is None:
        abort(404, description="There is no such job.")
    flash("The job is stopping; it will be removed shortly." if outcome == "cancelling" else "Job deleted.")
    return redirect(url_for("pages.jobs"), code=303)
