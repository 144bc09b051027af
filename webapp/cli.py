"""The `facesvg serve` and `facesvg worker` subcommands' arguments. What they run is in webapp.commands, imported
when one of them runs: every `facesvg` command builds this parser, and Flask, the job runner and their imports
would slow each `facesvg convert` (bench_startup)."""

from __future__ import annotations

import argparse
import importlib
import os
from collections.abc import Callable


def _later(name: str) -> Callable[[argparse.Namespace], int]:
    """The command webapp.commands.<name>, imported when it is called."""

    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module("webapp.commands"), name)(args)

    run.__name__ = name
    return run


def register_cli(subparsers) -> None:
    """Add the serve and worker subcommands to the facesvg parser."""
    p = subparsers.add_parser("serve", help="serve the web UI (waitress)")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=5000, help="port (default 5000)")
    p.add_argument("--workers", type=int, default=None, help="conversion worker processes (default 2)")
    p.add_argument("--threads", type=int, default=8, help="HTTP request threads (default 8)")
    p.add_argument("--queue", help="'embedded' (default) or redis://host:port/db (env FACESVG_QUEUE)")
    p.add_argument("--instance", help="instance folder for the job table, results and secret key")
    p.set_defaults(func=_later("cmd_serve"))

    p = subparsers.add_parser("worker", help="run conversion jobs from the Redis queue (RQ backend)")
    p.add_argument("--queue", default=os.environ.get("FACESVG_QUEUE"), help="redis://host:port/db")
    p.add_argument("--burst", action="store_true", help="exit when the queue is empty")
    p.set_defaults(func=_later("cmd_worker"))
