"""Warm a worker before it takes jobs: `converter.warm` compiles (or loads) every JIT-compiled kernel.

The first call of numba kernels holds the GIL for seconds (BENCHMARKS.md, start-up, for all of them on a fresh
install; longer on a busy machine), which would starve the lease heartbeat of the first job. Done once per worker
process (embedded) or once in the RQ worker's main process, before it forks work horses, so every horse inherits
the warm code. With the kernels already cached (`facesvg warm`, `make setup`) it costs a worker little: it loads them.
"""

from __future__ import annotations

import logging

from converter import warm

log = logging.getLogger("facesvg.webapp")


def warm_converter() -> None:
    """converter.warm.warm(), logged; a failure is logged and the worker goes on (warming is an optimisation)."""
    try:
        log.info("worker warm-up: %s", warm.warm().summary())
    except Exception as exc:  # warming is an optimisation; a failure here must not stop the worker
        log.warning("worker warm-up skipped: %s: %s", type(exc).__name__, exc)
