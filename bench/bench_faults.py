"""Web robustness figures (issue 17): fault runs (SIGKILL of server, workers, RQ workers), limits under a burst,
and the time from a crash to the affected jobs finishing after the restart."""

from __future__ import annotations

import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

TITLE = "Web robustness: kills, restarts, limits (issue 17)"
SEEDS = (1,)
JOBS = 20
KILLS = 3
BURST = 72  # submissions sent at once by 6 clients (one API key each) for the limits figure


def _row(name: str, out) -> str:
    kills = ", ".join(f"{k} {v}" for k, v in sorted(out.kills.items()))
    rec = f"{min(out.recovery):.1f}–{max(out.recovery):.1f}" if out.recovery else "—"
    return (f"| {name} | {out.jobs} | {kills} | {out.restarts} | {out.done} | {out.failed} | {out.lost} | "
            f"{out.duplicated} | {out.deleted} | {rec} | {out.seconds:.0f} |")


def _burst() -> str:
    """A burst of submissions against rate limit 10/min and queue cap 15: how many were refused, and how."""
    import requests

    from web.conftest import glb_bytes
    from web.faults import TINY, Serve

    folder = Path(tempfile.mkdtemp(prefix="bench-faults-"))
    keys = [f"bench-key-{k}" for k in range(6)]
    server = Serve(folder / "inst", workers=1, env={"FACESVG_RATE_LIMIT": "10", "FACESVG_QUEUE_CAP": "15",
                                                    "FACESVG_API_KEYS": ",".join(keys)})
    server.wait_up()
    codes: list[int] = []
    retry: list[str] = []
    lock = threading.Lock()
    data = glb_bytes()

    def client(k: int) -> None:
        for _ in range(BURST // 6):
            r = requests.post(f"{server.url}/api/v1/jobs", data=TINY, files={"file": ("c.glb", data)}, timeout=60,
                              headers={"Authorization": f"Bearer {keys[k]}"})
            with lock:
                codes.append(r.status_code)
                if r.status_code in (429, 503):
                    retry.append(r.headers.get("Retry-After", ""))

    t = time.perf_counter()
    threads = [threading.Thread(target=client, args=(k,)) for k in range(6)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    took = time.perf_counter() - t
    server.stop()
    counts = {c: codes.count(c) for c in sorted(set(codes))}
    return (f"Burst: {len(codes)} submissions from 6 concurrent clients (one API key each) in {took:.1f} s against "
            f"`FACESVG_RATE_LIMIT=10` and `FACESVG_QUEUE_CAP=15`: " +
            ", ".join(f"{n} × {c}" for c, n in counts.items()) +
            f"; every refusal carried Retry-After ({len(retry)} of {sum(v for c, v in counts.items() if c != 202)}).")


def _upload_limit() -> str:
    """A declared 300 MiB POST to `facesvg serve` (100 MB limit): bytes the client got to send before the 413."""
    from web.faults import Serve, oversized_post

    folder = Path(tempfile.mkdtemp(prefix="bench-faults-"))
    server = Serve(folder / "inst", workers=1).wait_up()
    try:
        t = time.perf_counter()
        answer, sent = oversized_post(server.port, 300 << 20)
        took = time.perf_counter() - t
    finally:
        server.stop()
    status = answer.split(b"\r\n", 1)[0].decode(errors="replace")
    return (f"Upload limit: a POST declaring 300 MiB got `{status}` after the client had sent {sent / 1024:.0f} KiB "
            f"of the body ({took * 1000:.0f} ms); the body is never read.")


def run() -> str:
    """Fault runs on both backends, the second-serve run, and the limits burst; markdown."""
    from web.faults import embedded_run, rq_run, second_serve_run

    rows = []
    for seed in SEEDS:
        with tempfile.TemporaryDirectory(prefix="bench-faults-") as d:
            rows.append(_row(f"embedded, seed {seed}", embedded_run(Path(d) / "inst", seed, JOBS, KILLS)))
    with tempfile.TemporaryDirectory(prefix="bench-faults-") as d:
        out, code, err, _, _ = second_serve_run(Path(d) / "inst", JOBS)
        out.kills = {"second serve": 1}
        rows.append(_row(f"second serve (exit {code})", out))
    redis_note = ""
    import shutil

    exe = shutil.which("redis-server")
    if exe:
        import subprocess

        from web.conftest import free_port

        port = free_port()
        with tempfile.TemporaryDirectory(prefix="bench-faults-") as d:
            proc = subprocess.Popen([exe, "--port", str(port), "--bind", "127.0.0.1", "--save", "",
                                     "--appendonly", "no", "--dir", d], stdout=subprocess.DEVNULL)
            try:
                time.sleep(0.5)
                url = f"redis://127.0.0.1:{port}/0"
                rows.append(_row("RQ, seed 1", rq_run(Path(d) / "inst", url, 1, JOBS, KILLS)))
            finally:
                proc.terminate()
                proc.wait(10)
    else:
        redis_note = "\n(RQ row skipped: redis-server is not installed.)\n"
    table = "\n".join([
        "| run | jobs | kills | restarts | done | failed | lost | duplicated | deleted | crash → done (s) | run (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|", *rows])
    return (f"Each run: {JOBS} tiny jobs (48 px cube), 2 workers, 6 s leases, `FACESVG_RETRIES=1`; kills are SIGKILL at "
            "random points while jobs run (seeded), followed by a restart of whatever was killed. *crash → done* "
            "is the time from a kill to the last job that was running at that moment being done (it includes "
            "the lease expiry, the restart and the worker's start-up, which dominates on this machine). "
            "A job fails only when it is killed on both of its attempts.\n\n"
            f"{table}\n{redis_note}\n{_burst()}\n\n{_upload_limit()}\n")
