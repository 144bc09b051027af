"""Limits checked before any work: per-client submission rate, queue cap, and options that make sense.

Both refusals carry Retry-After. The body size limit (MAX_CONTENT_LENGTH, FACESVG_MAX_UPLOAD_MB) is enforced by
Werkzeug, which refuses a declared length up front and stops a chunked body once it passes the limit, and by the
WSGI server while it reads (waitress `max_request_body_size`, set to server_body_limit).

A refused body is still read, and thrown away, up to FACESVG_DRAIN_MB past the limit (by default as much again
as the limit): a client that sends its whole body before reading the answer (Python's urllib, many scripts)
then gets the 413 and its JSON message. A server that stops reading and closes the socket while the client
still sends makes the kernel reset the connection, and the client sees "connection reset" instead. Above the
drain bound a declared length is refused as soon as the headers arrive (waitress answers its own plain 413 and
closes): such a client may see the reset; a browser never gets there, the upload form checks sizes first.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque

from flask import current_app, g, jsonify, render_template, request

from converter.errors import InputError

SUBMIT_ENDPOINTS = ("api.post_job", "pages.submit", "live.sample")  # live.sample: the sample's puppet
FORM_SLACK = 1 << 20  # room for the option fields and multipart framing beside the largest upload
DRAIN_CHUNK = 1 << 16


def upload_limit(config) -> int:
    """The largest request body the app takes, in bytes (MAX_CONTENT_LENGTH; the upload form checks against it)."""
    return int(config["MAX_CONTENT_LENGTH"])


def drain_limit(config) -> int:
    """Bytes past the upload limit still read and discarded to answer 413 (FACESVG_DRAIN_MB; default the limit)."""
    raw = config.get("FACESVG_DRAIN_MB")
    if raw is None or raw == "":
        return upload_limit(config)
    return max(int(float(raw) * (1 << 20)), 0)


def server_body_limit(config) -> int:
    """The WSGI server's own body limit: past it the server refuses without reading (waitress)."""
    return upload_limit(config) + FORM_SLACK + drain_limit(config)


def size_text(n: int) -> str:
    """A byte count as the form and messages show it: '100 MB', '1.5 MB', '64 KB'."""
    if n >= 1 << 20:
        mb = n / (1 << 20)
        return f"{mb:.0f} MB" if mb.is_integer() or mb >= 100 else f"{mb:.1f} MB"
    return f"{max(n / 1024, 1):.0f} KB" if n >= 1024 else f"{n} bytes"


def too_large_message(config) -> str:
    """What a 413 says: the limit and what to do."""
    return (f"The upload is larger than the {size_text(upload_limit(config))} limit; reduce the file (fewer frames, a "
            ".glb with meshopt compression) or ask the administrator to raise FACESVG_MAX_UPLOAD_MB.")


def drain_refused_body(environ: dict, config) -> int:
    """Read and discard a refused request's body when it ends within the drain bound; bytes read.

    Only then: a longer declared body is left unread (reading it all would cost as much as taking it).
    """
    stream = environ.get("wsgi.input")
    if stream is None:
        return 0
    bound = server_body_limit(config)
    try:
        declared = int(environ.get("CONTENT_LENGTH") or -1)
    except ValueError:
        return 0
    if declared < 0 and not environ.get("wsgi.input_terminated"):
        return 0  # no length and no end marker: reading could wait for ever
    if declared > bound:
        return 0
    left = declared if declared >= 0 else bound
    total = 0
    try:
        while left > 0:
            data = stream.read(min(DRAIN_CHUNK, left))
            if not data:
                break
            total += len(data)
            left -= len(data)
    except (OSError, ValueError):  # the client gave up; nothing left to answer
        pass
    return total


class RateLimiter:
    """At most `limit` submissions per `window` seconds per client (a sliding window of timestamps)."""

    def __init__(self, limit: int, window: float = 60.0, max_clients: int = 10000) -> None:
        self.limit, self.window, self.max_clients = int(limit), float(window), max_clients
        self.hits: dict[str, deque] = {}
        self.lock = threading.Lock()

    def check(self, client: str, now: float | None = None) -> float:
        """Record a submission; 0 if allowed, else the seconds until the client may submit again."""
        if self.limit <= 0:
            return 0.0
        now = time.monotonic() if now is None else now
        with self.lock:
            if len(self.hits) > self.max_clients:  # forget idle clients rather than grow without bound
                for key in [k for k, q in self.hits.items() if not q or q[-1] < now - self.window]:
                    del self.hits[key]
            q = self.hits.setdefault(client, deque())
            while q and q[0] <= now - self.window:
                q.popleft()
            if len(q) >= self.limit:
                return max(q[0] + self.window - now, 0.1)
            q.append(now)
            return 0.0


def client_key() -> str:
    """Who is submitting, for the rate limit: the API key or session id when set, else the remote address."""
    return getattr(g, "client", "") or request.remote_addr or "?"


def refuse(code: int, message: str, retry_after: float):
    """A 429/503 answer (JSON on the API, the error page otherwise) with Retry-After in whole seconds."""
    seconds = max(int(math.ceil(retry_after)), 1)
    if request.path.startswith("/api/"):
        response = jsonify(error=message, status=code, retry_after=seconds)
    else:
        title = "Too many submissions" if code == 429 else "The queue is full"
        response = current_app.make_response(render_template("error.html", code=code, title=title,
                                                             message=message))
    response.status_code = code
    response.headers["Retry-After"] = str(seconds)
    return response


def check_submission():
    """before_request: refuse a submission over the rate limit (429) or while the queue is full (503)."""
    if request.method != "POST" or request.endpoint not in SUBMIT_ENDPOINTS:
        return None
    limiter: RateLimiter = current_app.extensions["facesvg_limiter"]
    wait = limiter.check(client_key())
    if wait:
        return refuse(429, f"too many submissions from you; wait {int(math.ceil(wait))} s and try again.", wait)
    cap = int(current_app.config.get("FACESVG_QUEUE_CAP") or 0)
    if cap:
        admissions: Admissions = current_app.extensions["facesvg_admissions"]
        active = current_app.extensions["facesvg_queue"].store.count_active()
        if not admissions.enter(active, cap):
            return refuse(503, f"the server has {active} jobs waiting or running, its limit; try again in a "
                               "minute.", 30)
        g.facesvg_admitted = True
    return None


class Admissions:
    """Submissions admitted under the queue cap whose job is not stored yet, so a burst cannot overshoot it.

    A request counts here from its admission until it ends; by then its job (if any) is in the store's active
    count. In between it is counted twice, which can only refuse a little early, never admit past the cap.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pending = 0

    def enter(self, active: int, cap: int) -> bool:
        """Admit one more submission when active + those in flight stay under cap."""
        with self._lock:
            if active + self._pending >= cap:
                return False
            self._pending += 1
            return True

    def leave(self) -> None:
        """The admitted request ended."""
        with self._lock:
            self._pending = max(self._pending - 1, 0)


def _leave_admission(exc: BaseException | None = None) -> None:
    if g.pop("facesvg_admitted", False):
        current_app.extensions["facesvg_admissions"].leave()


def check_options(options: dict) -> None:
    """Frame choices consistent with the frame range (ConversionOptions already checked each value alone)."""
    start = int(options.get("start") or 0)
    end = options.get("end")
    frame = options.get("frame")
    neutral = options.get("neutral_frame")
    if frame is not None:
        if frame < start or (end is not None and frame >= end):
            upper = f" and below the “End frame” {end}" if end is not None else ""
            raise InputError(f"the “Still of frame” {frame} is outside the frames converted; choose a frame from "
                             f"the “First frame” {start}{upper}.")
    if neutral is not None and neutral < 0:
        raise InputError("the “Neutral frame” must be 0 or more.")
    if end is not None and end - start > 100000:
        raise InputError("the frame range is longer than 100000 frames; choose a shorter range.")


def install(app) -> None:
    """Create the limiter from FACESVG_RATE_LIMIT (submissions per minute per client) and hook the checks."""
    app.extensions["facesvg_limiter"] = RateLimiter(int(app.config.get("FACESVG_RATE_LIMIT") or 0))
    app.extensions["facesvg_admissions"] = Admissions()
    app.before_request(check_submission)
    app.teardown_request(_leave_admission)
