"""The live page: one of the user's puppet results driven by a `facesvg live` feed, with the feed's state, packet
rate, last packet's age and strongest weights (static/live.js connects and drives; this module picks and checks).

The web app does not start the bridge itself. It would open UDP and WebSocket ports on the server for whoever can
reach this page (with API keys on, for every key holder), bind them once per server process, and outlive the page
that asked; and the phone that tracks must reach the machine the bridge runs on, which is the user's choice to make
(`--host 0.0.0.0`). The page shows the exact command instead.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from flask import Blueprint, current_app, g, redirect, render_template, request, url_for
from werkzeug.datastructures import ImmutableMultiDict

from converter.errors import InputError
from converter.live.ports import Ports
from converter.outputs import OUTPUTS
from webapp.jobstore import DONE, FAILED, FINISHED, Job
from webapp.messages import user_words
from webapp.pages import queue
from webapp.security import PAGE_CSP, may_see
from webapp.storage import is_job_id
from webapp.submit import create_job

live = Blueprint("live", __name__)

PUPPET = "puppet"  # the output kind (and its main file's key) the page plays
PORTS = Ports()  # the bridge's default ports, as `facesvg live` listens without flags
DEFAULT_FEED = f"ws://127.0.0.1:{PORTS.ws}"  # what `facesvg live` prints for a player on its own machine
QUIET_SECONDS = 2  # a connected feed without a packet for this long reads "no packets for N s"
RETRY_SECONDS = 2  # the page tries a feed that is not up (or went away) again after this long
MAX_FEED = 2000  # characters of a feed address the page looks at
# The page's own script connects to the feed the user names, on any host: WebSockets only, nothing else widened.
LIVE_CSP = PAGE_CSP + "; connect-src 'self' ws: wss:"
SOURCES = (("Live Link Face", PORTS.llf, "its Live Link target"), ("iFacialMocap", PORTS.ifm, "its destination"),
           ("a VMC sender (VSeeFace, Warudo, ...)", PORTS.vmc, "its VMC protocol send address"))


def feed_problem(url: str, secure: bool = False) -> str:
    """Why this page cannot open a feed at url, in one sentence ('' when it can); secure: the page came over https."""
    text = url.strip()
    shown = text if len(text) <= 80 else text[:77] + "..."
    if not text:
        return f"give the feed's WebSocket address, such as {DEFAULT_FEED}."
    if len(text) > MAX_FEED or any(c.isspace() or ord(c) < 32 for c in text):
        return f"“{shown}” is not a WebSocket address (it has spaces in it); give one such as {DEFAULT_FEED}."
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        return f"“{shown}” is not a WebSocket address: its port is not a number from 1 to 65535."
    if parts.scheme in ("http", "https"):
        fixed = ("wss" if parts.scheme == "https" else "ws") + text[len(parts.scheme):]
        return f"“{shown}” is a web page's address; a feed's starts with ws:// (here: {fixed})."
    if parts.scheme not in ("ws", "wss"):
        return f"“{shown}” is not a WebSocket address; give one such as {DEFAULT_FEED}."
    if not parts.hostname:
        return f"“{shown}” names no host; give one such as {DEFAULT_FEED}."
    if port == 0:
        return f"“{shown}” has port 0; give the port “facesvg live” printed (by default {PORTS.ws})."
    if parts.fragment or text.endswith("#"):
        return f"“{shown}” has a #fragment, which browsers refuse in a WebSocket address; leave it out."
    if secure and parts.scheme == "ws":
        return ("this page came over https, where browsers open only secure feeds (wss://); open the page over "
                "http on the machine that runs `facesvg live`, or put the bridge behind a TLS proxy.")
    return ""


def ws_port(url: str) -> int:
    """The port a feed address names (its scheme's default when it names none)."""
    parts = urlsplit(url)
    return parts.port or (443 if parts.scheme == "wss" else 80)


def bridge_command(url: str) -> str:
    """The `facesvg live` command that serves a feed at url: every interface (a phone's stream), its port if not
    the default."""
    port = ws_port(url)
    return "facesvg live --host 0.0.0.0" + (f" --ws-port {port}" if port != PORTS.ws else "")


def is_puppet(job: Job) -> bool:
    """True when the job makes a puppet."""
    return (job.options or {}).get("to") == PUPPET


def puppet_results(limit: int = 200) -> list[Job]:
    """The finished puppets this browser may see, newest first."""
    client = getattr(g, "client", "")
    jobs = queue().recent(limit if not client else max(limit * 20, 500))
    return [j for j in jobs if j.state == DONE and is_puppet(j) and may_see(j)][:limit]


def chosen(job_id: str, puppets: list[Job]) -> tuple[Job | None, str]:
    """The job to play (the newest puppet when none is named) and what is wrong with the one named ('' if nothing)."""
    if not job_id:
        return (puppets[0] if puppets else None), ""
    job = queue().get(job_id) if is_job_id(job_id) else None
    if job is None or not may_see(job):
        return None, "There is no such result; it may have been deleted or cleaned up. Pick another puppet."
    if not is_puppet(job):
        kind = OUTPUTS.get((job.options or {}).get("to", "svg"))
        made = kind.label if kind else "another output"
        return None, f"That job made {made}, not a puppet; only a puppet can follow a live stream. Pick a puppet."
    if job.state == FAILED:
        return None, f"That puppet could not be made: {user_words(job.message) or 'the conversion failed'}"
    if job.state in FINISHED and job.state != DONE:
        return None, "That puppet was cancelled before it was made. Pick another one."
    if queue().storage.result_path(job.id, PUPPET) is None and job.state == DONE:
        return None, "That puppet's file is gone from the server; convert the face again."
    return job, ""


@live.get("/live")
def page():
    """The live page: ?job=ID picks the puppet, ?feed=ws://... the feed (default: the bridge's own address)."""
    puppets = puppet_results()
    job, job_error = chosen(request.args.get("job", "").strip(), puppets)
    feed = request.args.get("feed", DEFAULT_FEED)[:MAX_FEED].strip()
    feed_error = feed_problem(feed, secure=request.is_secure)
    building = job is not None and job.state != DONE
    src = url_for("api.get_result_kind", job_id=job.id, kind=PUPPET, paused=1) if job and not building else ""
    html = render_template("live.html", puppets=puppets, job=job, job_error=job_error, building=building,
                           src=src, feed=feed, feed_error=feed_error,
                           command=bridge_command(feed) if not feed_error else bridge_command(DEFAULT_FEED),
                           ws_default=PORTS.ws, sources=SOURCES, quiet=QUIET_SECONDS, retry=RETRY_SECONDS)
    status = 404 if job_error.startswith("There is no such") else 400 if feed_error or job_error else 200
    return html, status, {"Content-Security-Policy": LIVE_CSP}


@live.post("/live/sample")
def sample():
    """Make the bundled sample's puppet (an ordinary job) and come back to the live page, which waits for it."""
    current_app.extensions["facesvg_cleanup"].maybe_run()
    form = ImmutableMultiDict([("sample", "1"), ("to", PUPPET)])
    feed = request.form.get("feed", DEFAULT_FEED)[:MAX_FEED]
    try:
        job = create_job(queue(), current_app.config, form, ImmutableMultiDict(), client=getattr(g, "client", ""))
    except InputError as exc:
        return render_template("error.html", code=400, title="No sample puppet", message=user_words(str(exc))), 400
    return redirect(url_for("live.page", job=job.id, feed=feed), code=303)
