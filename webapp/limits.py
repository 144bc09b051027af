"""Limits checked before any work: per-client submission rate, queue cap, and options that make sense.

Both refusals carry Retry-After. The body size limit is enforced by the WSGI server while it reads
(waitress `max_request_body_size`) and by Werkzeug's MAX_CONTENT_LENGTH, which refuses a declared length up
front and stops a chunked body once it passes the limit.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque

from flask import current_app, g, jsonify, render_template, request

from converter.errors import InputError

SUBMIT_ENDPOINTS = ("api.post_job", "pages.submit")


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
