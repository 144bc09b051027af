"""Who may do what: cross-site request refusal, optional API keys scoping jobs, and security headers.

API keys (env FACESVG_API_KEYS, comma-separated) are sent as `Authorization: Bearer KEY` or `X-API-Key: KEY`.
When keys are set the API needs one (or the browser session of the HTML UI) and every job belongs to the key
(or session) that submitted it: the list, the job, its results and DELETE answer only to that client.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import hmac
import re
import secrets
from pathlib import Path
from urllib.parse import urlsplit

from flask import Flask, abort, current_app, g, request, session

UNSAFE = ("POST", "PUT", "PATCH", "DELETE")
PAGE_CSP = ("default-src 'self'; img-src 'self' data: blob:; object-src 'self'; frame-src 'self'; "
            "frame-ancestors 'self'; form-action 'self'; base-uri 'none'")
OTHER_CSP = "default-src 'none'; frame-ancestors 'self'; base-uri 'none'"  # JSON, images, downloads, errors
INLINE = re.compile(r"<(script|style)>(.*?)</\1>", re.DOTALL)  # inline blocks without attributes


def _inline_hashes(path: str) -> dict[str, str]:
    """The CSP sources ('sha256-...') of an HTML file's inline script and style blocks, by tag."""
    text = Path(path).read_text(encoding="utf-8")
    hashes: dict[str, list[str]] = {"script": [], "style": []}
    for tag, body in INLINE.findall(text):
        digest = base64.b64encode(hashlib.sha256(body.encode("utf-8")).digest()).decode()
        hashes[tag].append(f"'sha256-{digest}'")
    return {tag: " ".join(sources) for tag, sources in hashes.items()}


@functools.lru_cache(maxsize=16)
def _static_page_csp(path: str, mtime: float) -> str:
    """The CSP of a static HTML page: same-origin loads only, its own inline blocks allowed by their hashes."""
    hashes = _inline_hashes(path)
    return (f"default-src 'self'; script-src 'self' {hashes['script']}; "
            f"style-src 'self' {hashes['style']}; img-src 'self' data: blob:; connect-src 'self'; "
            "object-src 'none'; frame-ancestors 'self'; form-action 'none'; base-uri 'none'")


@functools.lru_cache(maxsize=16)
def _self_contained_csp(path: str, mtime: float, connect: str) -> str:
    """The CSP of a generated self-contained page (the player): only its own inline blocks, no loads at all."""
    hashes = {tag: sources or "'none'" for tag, sources in _inline_hashes(path).items()}
    return (f"default-src 'none'; script-src {hashes['script']}; style-src {hashes['style']}; "
            f"img-src data: blob:; connect-src {connect}; "
            "object-src 'none'; frame-ancestors 'self'; form-action 'none'; base-uri 'none'")


def self_contained_csp(path: Path, websockets: bool = False) -> str:
    """The CSP for a generated HTML result file (recomputed when the file changes); websockets: it may open the
    WebSocket feed its user names (the puppet's Live field), and nothing else."""
    return _self_contained_csp(str(path), path.stat().st_mtime, "ws: wss:" if websockets else "'none'")


def static_page_csp(filename: str) -> str:
    """The CSP for a static HTML file served from the static folder (recomputed when the file changes)."""
    path = Path(current_app.static_folder) / filename
    return _static_page_csp(str(path), path.stat().st_mtime)


def parse_keys(value: str | None) -> tuple[str, ...]:
    """The API keys of a comma-separated setting (blank entries dropped)."""
    return tuple(k.strip() for k in (value or "").split(",") if k.strip())


def key_id(key: str) -> str:
    """A stable, non-secret id for a key (what job records store)."""
    return "key:" + hashlib.sha256(key.encode()).hexdigest()[:16]


def same_origin(url: str) -> bool:
    """True when url (an Origin or Referer value) names this server's scheme, host and port."""
    if not url or url == "null":
        return False
    parts = urlsplit(url)
    return (parts.scheme, parts.netloc.lower()) == (request.scheme, request.host.lower())


def check_origin() -> None:
    """Refuse (403) unsafe requests a browser sent from another site; tools that send neither header pass."""
    if request.method not in UNSAFE:
        return
    origin = request.headers.get("Origin")
    referer = request.headers.get("Referer")
    if origin is not None:
        ok = same_origin(origin)
    elif referer is not None:
        ok = same_origin(referer)
    else:
        ok = True  # curl, scripts and SDKs: not a browser on another page (browsers send Origin on POST)
    if not ok:
        abort(403, description="this request came from another web site and was refused; use facesvg's own page "
                               "or the API from a program.")


def session_client() -> str:
    """The browser session's client id (created on first use; kept in the signed SameSite cookie)."""
    if "client" not in session:
        session["client"] = "session:" + secrets.token_hex(8)
    return session["client"]


def identify() -> None:
    """Set g.client: the API key's id, the session's id, or '' when keys are off; 401 without one on the API."""
    keys = current_app.config.get("FACESVG_API_KEYS") or ()
    g.client = ""
    if not keys:
        return
    given = request.headers.get("X-API-Key", "")
    auth = request.headers.get("Authorization", "")
    if auth.lower().startswith("bearer "):
        given = auth[7:].strip()
    if given:
        if not any(hmac.compare_digest(given, k) for k in keys):
            abort(401, description="this API key is not valid; check the key or ask the administrator.")
        g.client = key_id(given)
        return
    if request.path.startswith("/api/") and request.endpoint not in ("api.health", "api.openapi") \
            and "client" not in session:
        abort(401, description="this API needs a key: send it as 'Authorization: Bearer KEY'.")
    g.client = session_client()


def may_see(job) -> bool:
    """True when the current client may see and delete this job (always, when keys are off)."""
    client = getattr(g, "client", "")
    return not client or job.client == client


def security_headers(response):
    """CSP, frame protection, nosniff and Referrer-Policy on every response (pages, static files, errors)."""
    response.headers.setdefault("X-Content-Type-Options", "nosniff")
    response.headers.setdefault("Referrer-Policy", "same-origin")
    response.headers.setdefault("X-Frame-Options", "SAMEORIGIN")
    html = response.mimetype in ("text/html", "application/xhtml+xml")
    if html and response.status_code == 200 and request.endpoint == "static" and request.view_args:
        response.headers.setdefault("Content-Security-Policy", static_page_csp(request.view_args["filename"]))
    response.headers.setdefault("Content-Security-Policy", PAGE_CSP if html else OTHER_CSP)
    return response


def install(app: Flask) -> None:
    """Hook the checks and headers into the app."""
    app.config["FACESVG_API_KEYS"] = parse_keys(app.config.get("FACESVG_API_KEYS")) \
        if isinstance(app.config.get("FACESVG_API_KEYS"), str) else tuple(app.config.get("FACESVG_API_KEYS") or ())
    if app.config.get("SESSION_COOKIE_SAMESITE") not in ("Lax", "Strict"):
        app.config["SESSION_COOKIE_SAMESITE"] = "Lax"
    app.config["SESSION_COOKIE_HTTPONLY"] = True
    app.before_request(check_origin)
    app.before_request(identify)
    app.after_request(security_headers)
