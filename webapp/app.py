"""facesvg web UI: Flask application factory (upload, live job page, result player, REST API /api/v1)."""

from __future__ import annotations

import atexit
import os
import secrets
import threading
import time
from pathlib import Path

from flask import Flask, jsonify, render_template, request
from flask_wtf.csrf import CSRFError, CSRFProtect
from werkzeug.exceptions import HTTPException

from converter.bundled import asset_dir, sample_path
from webapp import limits, security
from webapp.api import api
from webapp.jobs import make_queue
from webapp.lease import InstanceLock
from webapp.live import live
from webapp.pages import pages
from webapp.strictjson import StrictJSONProvider

ROOT = Path(__file__).resolve().parents[1]
csrf = CSRFProtect()

DEFAULTS = {
    "MAX_CONTENT_LENGTH": 100 * 1024 * 1024,  # upload limit -> 413
    "FACESVG_QUEUE": "embedded",  # or redis://host:port/db for the RQ backend
    "FACESVG_WORKERS": 2,  # embedded worker pool size
    "FACESVG_EXECUTOR": "process",  # embedded pool kind: process (default) or thread
    "FACESVG_RETENTION_HOURS": 168.0,  # finished jobs older than this are removed
    "FACESVG_CLEANUP_INTERVAL": 600.0,  # seconds between retention sweeps
    "FACESVG_MAX_UNZIPPED_MB": 1024,  # zip inputs expanding beyond this are refused
    "FACESVG_PREVIEW_FRAMES": 48,  # 3D prerender frames per job (spread evenly)
    "FACESVG_JOB_TIMEOUT": 3600,  # RQ job timeout in seconds
    "FACESVG_LEASE_SECONDS": 30.0,  # a worker's claim on a job expires unless renewed within this time
    "FACESVG_RETRIES": 1,  # a job whose worker died is re-queued this many times, then failed
    "FACESVG_QUEUE_CAP": 200,  # queued + running jobs beyond which submissions get 503 (0: no cap)
    "FACESVG_RATE_LIMIT": 30,  # submissions per minute per client (API key, session or address; 0: off)
    "FACESVG_API_KEYS": "",  # comma-separated; when set the API needs a key and jobs are scoped to it
    "FACESVG_SAMPLE": str(sample_path()),
    "FACESVG_DRAIN_MB": None,  # a refused upload is still read up to this far past the limit (None: the limit again)
    "WTF_CSRF_TIME_LIMIT": None,  # tokens live as long as the session
}
ENV_KEYS = {  # FACESVG_* environment variables override defaults; explicit config overrides both
    "FACESVG_QUEUE": str, "FACESVG_WORKERS": int, "FACESVG_EXECUTOR": str, "FACESVG_RETENTION_HOURS": float,
    "FACESVG_CLEANUP_INTERVAL": float, "FACESVG_MAX_UNZIPPED_MB": int, "FACESVG_PREVIEW_FRAMES": int,
    "FACESVG_STORAGE": str, "FACESVG_SAMPLE": str, "FACESVG_JOB_TIMEOUT": int, "FACESVG_LEASE_SECONDS": float,
    "FACESVG_RETRIES": int, "FACESVG_QUEUE_CAP": int, "FACESVG_RATE_LIMIT": int, "FACESVG_API_KEYS": str,
    "FACESVG_DRAIN_MB": float,
}


def create_app(config: dict | None = None) -> Flask:
    """Build the app: config from defaults, FACESVG_* environment and the given dict; start the job queue."""
    app = Flask(
        __name__,
        template_folder=str(asset_dir("webapp", "templates")),
        static_folder=str(asset_dir("webapp", "static")),
        # A checkout keeps its instance folder beside the code; an installed wheel uses Flask's default
        # (sys.prefix/var/webapp-instance), never site-packages.
        instance_path=(config or {}).get("INSTANCE_PATH") or os.environ.get("FACESVG_INSTANCE")
        or (str(ROOT / "instance") if (ROOT / "pyproject.toml").is_file() else None),
    )
    app.json = StrictJSONProvider(app)  # before the Jinja environment exists: its tojson filter uses it too
    app.config.update(DEFAULTS)
    for key, cast in ENV_KEYS.items():
        if os.environ.get(key):
            app.config[key] = cast(os.environ[key])
    if os.environ.get("FACESVG_MAX_UPLOAD_MB"):
        app.config["MAX_CONTENT_LENGTH"] = int(os.environ["FACESVG_MAX_UPLOAD_MB"]) * 1024 * 1024
    app.config.update(config or {})
    instance = Path(app.instance_path)
    instance.mkdir(parents=True, exist_ok=True)
    lock = InstanceLock(instance).acquire()  # before anything reads or recovers the job table (InstanceBusy)
    app.config.setdefault("FACESVG_STORAGE", str(instance / "jobs"))
    app.config.setdefault("FACESVG_DB", str(instance / "jobs.sqlite3"))
    if not app.config.get("SECRET_KEY"):
        app.config["SECRET_KEY"] = os.environ.get("FACESVG_SECRET_KEY") or _instance_secret(instance)

    try:
        queue = make_queue(app.config)
    except BaseException:
        lock.release()
        raise
    queue.instance_lock = lock
    app.extensions["facesvg_queue"] = queue
    atexit.register(_close_quietly, queue)
    app.extensions["facesvg_cleanup"] = RetentionSweeper(queue, app.config)
    app.extensions["facesvg_cleanup"].maybe_run(force=True)  # then at most once per interval, on submissions

    csrf.init_app(app)

    csrf.exempt(api)  # the JSON API takes no cookies-based session; CSRF applies to the HTML forms
    app.register_blueprint(pages)
    app.register_blueprint(live)
    app.register_blueprint(api, url_prefix="/api/v1")
    _register_errors(app)
    security.install(app)
    limits.install(app)
    return app


def _close_quietly(queue) -> None:
    try:
        queue.close()
    except Exception:  # interpreter shutdown; nothing left to report to
        pass


def _instance_secret(instance: Path) -> str:
    """A secret key kept in the instance folder so sessions and CSRF tokens survive restarts."""
    path = instance / "secret_key"
    if not path.exists():
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as fh:
            fh.write(secrets.token_hex(32))
    return path.read_text().strip()


class RetentionSweeper:
    """Removes jobs past the retention at most once per interval, triggered by requests (no extra thread)."""

    def __init__(self, queue, config) -> None:
        self.queue, self.config = queue, config
        self.last = 0.0
        self.lock = threading.Lock()

    def maybe_run(self, force: bool = False) -> list[str]:
        """Sweep if the interval has passed (or force); returns removed job ids."""
        now = time.time()
        if not force and now - self.last < float(self.config["FACESVG_CLEANUP_INTERVAL"]):
            return []
        if not self.lock.acquire(blocking=False):
            return []
        try:
            self.last = now
            return self.queue.cleanup(float(self.config["FACESVG_RETENTION_HOURS"]) * 3600)
        finally:
            self.lock.release()


def wants_json() -> bool:
    """True for API requests (JSON errors), False for pages (HTML errors)."""
    return request.path.startswith("/api/")


def _register_errors(app: Flask) -> None:
    @app.errorhandler(CSRFError)
    def csrf_error(exc):
        return render_template("error.html", code=400, title="Form expired",
                               message="The form was missing its security token or it expired. Reload the page "
                                       "and try again."), 400

    @app.errorhandler(413)
    def too_large(exc):
        message = limits.too_large_message(app.config)
        limits.drain_refused_body(request.environ, app.config)  # so a client still sending reads this answer
        if wants_json():
            return jsonify(error=message, status=413), 413
        return render_template("error.html", code=413, title="File too large", message=message), 413

    @app.errorhandler(HTTPException)
    def http_error(exc: HTTPException):
        if wants_json():
            return jsonify(error=exc.description, status=exc.code), exc.code
        return render_template("error.html", code=exc.code, title=exc.name, message=exc.description), exc.code
