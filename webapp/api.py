"""REST API /api/v1 (JSON): submit, inspect, fetch results of, and delete conversion jobs."""

from __future__ import annotations

import io
import logging

from flask import Blueprint, abort, current_app, g, jsonify, request, send_file, url_for

from converter.errors import InputError
from converter.outputs import OUTPUTS, output_files
from webapp import strictjson
from webapp.eta import standing
from webapp.inspect import inspect_upload
from webapp.jobstore import DONE, Job, damaged
from webapp.messages import user_words
from webapp.openapi import openapi_document
from webapp.security import may_see, self_contained_csp
from webapp.storage import is_job_id, result_files
from webapp.submit import create_job, download_stem

api = Blueprint("api", __name__)
log = logging.getLogger("facesvg.webapp")
REPORT_SUFFIX = ".report.json"
LIVE_FEED_KIND = "puppet"  # the result file that may open a live WebSocket feed (its Live field, ?live=)


def queue():
    """The app's job queue."""
    return current_app.extensions["facesvg_queue"]


def find_job(job_id: str) -> Job:
    """The job or a 404."""
    job = queue().get(job_id) if is_job_id(job_id) else None
    if job is None or not may_see(job):
        abort(404, description=f"no job {job_id!r}; it may have been deleted or cleaned up.")
    return job


def public_job(job: Job) -> dict:
    """job_json, or the job shown as damaged (failed) when its stored record cannot be presented."""
    try:
        return job_json(job)
    except Exception as exc:  # a record the store could parse but that makes no sense: never break the answer
        log.warning("job %s: cannot present its record: %r", job.id, exc)
        return job_json(damaged(job, "its result could not be read"))


def job_json(job: Job) -> dict:
    """The public view of a job, with links."""
    data = {
        "id": job.id,
        "state": job.state,
        "stage": job.stage,
        "progress": round(job.progress, 4),
        "percent": int(job.progress * 100),
        "error": user_words(job.message) if job.state == "failed" else None,
        "filename": job.filename,
        "files": dict(job.names) or {"input": job.filename},  # role -> the user's file name (input, weights, ...)
        "input_kind": job.kind,
        "options": job.options,
        "created": job.created,
        "started": job.started,
        "finished": job.finished,
        **standing(queue(), job),
        "links": {
            "self": url_for("api.get_job", job_id=job.id),
            "page": url_for("pages.job_page", job_id=job.id),
        },
    }
    if job.state == DONE:
        kinds = queue().storage.available(job.id)
        data["result"] = job.result
        data["links"]["result"] = url_for("api.get_result", job_id=job.id)
        data["links"]["results"] = {k: url_for("api.get_result_kind", job_id=job.id, kind=k) for k in kinds}
        data["links"]["previews"] = {
            str(k): url_for("api.get_preview", job_id=job.id, frame=k) for k in job.result.get("preview_frames", [])
        }
    return data


@api.get("/health")
def health():
    """Liveness and the queue backend in use."""
    return jsonify(status="ok", backend=queue().name)


@api.get("/openapi.json")
def openapi():
    """The OpenAPI 3.1 description of this API."""
    return jsonify(openapi_document())


@api.get("/jobs")
def list_jobs():
    """Recent jobs, newest first."""
    try:
        limit = min(max(int(request.args.get("limit", 50)), 1), 500)
    except ValueError:
        abort(400, description="limit must be a whole number between 1 and 500.")
    return jsonify(jobs=[public_job(j) for j in visible_jobs(limit)])


def visible_jobs(limit: int) -> list[Job]:
    """The newest jobs the current client may see (all of them when API keys are off)."""
    if not getattr(g, "client", ""):
        return queue().recent(limit)
    return [j for j in queue().recent(max(limit * 20, 500)) if may_see(j)][:limit]


@api.post("/jobs")
def post_job():
    """Create a job from a multipart upload (field 'file', or sample=1) and option fields."""
    current_app.extensions["facesvg_cleanup"].maybe_run()
    try:
        job = create_job(queue(), current_app.config, request.form, request.files, strict=True,
                         client=getattr(g, "client", ""))
    except InputError as exc:
        return jsonify(error=user_words(str(exc)), status=400), 400
    response = jsonify(public_job(queue().get(job.id) or job))
    response.status_code = 202
    response.headers["Location"] = url_for("api.get_job", job_id=job.id)
    return response


@api.post("/inspect")
def inspect():
    """Describe an uploaded file without converting it: a face's clips, parts, nodes and morph targets, or a
    take's layout (the upload form's suggestions)."""
    upload = request.files.get("file")
    if upload is None or not upload.filename:
        return jsonify(error="send the file to describe in the field 'file'.", status=400), 400
    try:
        summary = inspect_upload(upload, int(current_app.config["FACESVG_MAX_UNZIPPED_MB"]) << 20,
                                 request.form.get("role", ""))
    except InputError as exc:
        return jsonify(error=user_words(str(exc)), status=400), 400
    return jsonify(summary)


@api.get("/jobs/<job_id>")
def get_job(job_id: str):
    """State, stage, progress, error and links of a job."""
    return jsonify(public_job(find_job(job_id)))


@api.delete("/jobs/<job_id>")
def delete_job(job_id: str):
    """Cancel a queued job or delete a finished one (204); a running job is asked to stop (202)."""
    find_job(job_id)
    outcome = queue().delete(job_id)
    if outcome is None:
        abort(404, description=f"no job {job_id!r}.")
    if outcome == "cancelling":
        return jsonify(id=job_id, state="cancelling"), 202
    return "", 204


def _finished_job(job_id: str) -> Job:
    job = find_job(job_id)
    if job.state != DONE:
        detail = job.message if job.state == "failed" else f"the job is {job.state}"
        abort(409, description=f"no result: {detail}.")
    return job


@api.get("/jobs/<job_id>/result")
def get_result(job_id: str):
    """The main output: the first file of the job's output kind (the SVG, or the fap2d package)."""
    job = _finished_job(job_id)
    kind = OUTPUTS.get(job.options.get("to", "svg"))
    if kind is None:
        abort(404, description=f"this job's output kind {job.options.get('to')!r} is not offered any more.")
    return _send(job, kind.files[0].key)


@api.get("/jobs/<job_id>/result/<kind>")
def get_result_kind(job_id: str, kind: str):
    """One output by kind: a file of an output kind (svg, svgz, fap2d, ...) or the report."""
    files = result_files()
    if kind not in files:
        abort(404, description=f"unknown result kind {kind!r}; use one of {', '.join(files)}.")
    return _send(_finished_job(job_id), kind)


@api.get("/jobs/<job_id>/preview/<int:frame>")
def get_preview(job_id: str, frame: int):
    """The 3D prerender (PNG) of one frame listed in result.preview_frames."""
    job = _finished_job(job_id)
    path = queue().storage.preview_path(job.id, frame)
    if path is None:
        abort(404, description=f"no prerender of frame {frame}; see result.preview_frames.")
    return send_file(path, mimetype="image/png", max_age=3600)


def _send(job: Job, kind: str):
    path = queue().storage.result_path(job.id, kind)
    if path is None:
        abort(404, description=f"this job has no {kind} output.")
    media = result_files()[kind][1]
    out = output_files().get(kind)
    suffix = out.suffix if out else REPORT_SUFFIX
    download = (out is not None and out.attachment) or request.args.get("download") in ("1", "true")
    source = io.BytesIO(strict_report(path)) if kind == "report" else path
    response = send_file(source, mimetype=media, as_attachment=download,
                         download_name=download_stem(job) + suffix, max_age=0)
    if kind == "svg":  # generated SVG shown inline: no scripts, no external loads
        response.headers["Content-Security-Policy"] = ("default-src 'none'; style-src 'unsafe-inline'; img-src data:; "
                                                       "frame-ancestors 'self'")
    elif media == "text/html":  # a generated page (the player): its own inline blocks by hash, no loads
        response.headers["Content-Security-Policy"] = self_contained_csp(path, websockets=kind == LIVE_FEED_KIND)
    return response


def strict_report(path) -> bytes:
    """A stored report as strict JSON: a non-finite figure (reports stored before they were cleaned) as null."""
    try:
        report = strictjson.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        abort(500, description="this job's stored report is damaged and cannot be served; delete the job and "
                               "convert the file again.")
    return strictjson.dumps(report, indent=1, sort_keys=True).encode()
