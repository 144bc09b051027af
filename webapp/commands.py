"""What `facesvg serve` (the web UI on waitress) and `facesvg worker` (an RQ worker for the Redis backend) run;
webapp.cli registers them."""

from __future__ import annotations

import argparse
import os
import signal
import sys

from converter import render
from converter.errors import InputError
from webapp import runner  # noqa: F401 - imported so forked RQ work horses start warm
from webapp.app import create_app
from webapp.lease import InstanceBusy
from webapp.limits import server_body_limit
from webapp.warmup import warm_converter

RQ_MAINTENANCE_SECONDS = 30  # how often an RQ worker cleans up jobs abandoned by a dead worker (RQ: 600)


def cmd_serve(args: argparse.Namespace) -> int:
    """Start the web UI with waitress (a production WSGI server) on host:port."""
    import waitress  # noqa: PLC0415 - the server is needed only by `serve`, not by every facesvg command

    config = {}
    if args.workers is not None:
        config["FACESVG_WORKERS"] = args.workers
    if args.queue:
        config["FACESVG_QUEUE"] = args.queue
    if args.instance:
        config["INSTANCE_PATH"] = os.path.abspath(args.instance)
    try:
        app = create_app(config)
    except InstanceBusy as exc:
        print(f"facesvg serve: {exc}", file=sys.stderr, flush=True)
        return 2
    # waitress refuses a larger body as it reads it (a declared Content-Length at once, a chunked one on the way);
    # below that it reads the body whole, so the app's 413 (JSON on the API) reaches a client that sends it all
    body_limit = server_body_limit(app.config)
    print(f"facesvg web UI on http://{args.host}:{args.port} ({app.extensions['facesvg_queue'].name} queue)",
          flush=True)
    signal.signal(signal.SIGTERM, _exit)
    try:
        waitress.serve(app, host=args.host, port=args.port, threads=args.threads, ident="facesvg",
                       max_request_body_size=body_limit)
    except KeyboardInterrupt:
        pass
    finally:
        # Stop the workers with the server; jobs they were running are re-queued when it starts again.
        app.extensions["facesvg_queue"].close(wait=False)
    return 0


def _exit(signum, frame) -> None:
    raise KeyboardInterrupt()


def cmd_worker(args: argparse.Namespace) -> int:
    """Work the facesvg RQ queue until stopped (or until empty with --burst)."""
    if not args.queue or not args.queue.startswith(("redis://", "rediss://", "unix://")):
        raise InputError("give the Redis URL with --queue redis://host:port/0 (or set FACESVG_QUEUE).")
    every = maintenance_seconds()
    from redis import Redis  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured
    from rq import Queue, Worker  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured

    # The pipeline (imported at the top) and pyrender load here, so each forked work horse starts warm.
    render._pyrender()
    warm_converter()  # JIT kernels compiled or loaded here are inherited by every work horse
    conn = Redis.from_url(args.queue)
    # RQ's maintenance (every 10 minutes by default) is what fails a job whose worker died after taking it from
    # the queue but before its horse claimed it; the server then re-queues it (RQQueue.get). Run it often, idle
    # too: an idle worker waits for work worker_ttl - 15 s at a time (405 s by default) and only between those
    # waits does it run maintenance, so such a job sat queued ~7 minutes once the queue had drained.
    Worker([Queue("facesvg", connection=conn)], connection=conn, maintenance_interval=every,
           worker_ttl=every + 15).work(burst=args.burst)
    return 0


def maintenance_seconds() -> int:
    """Seconds between an RQ worker's maintenance runs: FACESVG_RQ_MAINTENANCE_SECONDS, else RQ_MAINTENANCE_SECONDS."""
    raw = os.environ.get("FACESVG_RQ_MAINTENANCE_SECONDS", "").strip()
    if not raw:
        return RQ_MAINTENANCE_SECONDS
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if not 1 <= value <= 3600:
        raise InputError(f"FACESVG_RQ_MAINTENANCE_SECONDS={raw!r}: give whole seconds from 1 to 3600.")
    return value
