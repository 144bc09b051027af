"""Fault injection for the web service: real `facesvg serve` / `facesvg worker` processes killed with SIGKILL.

Used by tests/web/test_faults.py and bench/bench_faults.py. Loopback only; every wait is bounded.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import requests
from lxml import etree

from web.conftest import free_port, glb_bytes

ROOT = Path(__file__).resolve().parents[2]
TINY = {"size": "48", "occlusion": "0"}
FAST_ENV = {"FACESVG_LEASE_SECONDS": "6", "FACESVG_PREVIEW_FRAMES": "2", "FACESVG_RATE_LIMIT": "0",
            "FACESVG_RETRIES": "1", "PYOPENGL_PLATFORM": "egl"}


def children(pid: int) -> list[int]:
    """Direct child process ids of pid (from /proc; Linux)."""
    out = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as fh:
                out += [int(x) for x in fh.read().split()]
    except (FileNotFoundError, ProcessLookupError):
        pass
    return out


def cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def alive(pid: int) -> bool:
    """True while pid exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def kill9(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


class Serve:
    """`facesvg serve` on a free loopback port for an instance folder."""

    def __init__(self, instance: Path, workers: int = 2, env: dict | None = None, queue: str | None = None) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        args = [sys.executable, "-m", "converter.cli", "serve", "--port", str(self.port), "--workers", str(workers),
                "--instance", str(instance)]
        if queue:
            args += ["--queue", queue]
        self.proc = subprocess.Popen(args, cwd=ROOT, env={**os.environ, **FAST_ENV, **(env or {})},
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

    def wait_up(self, timeout: float = 90) -> Serve:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise AssertionError(f"server exited {self.proc.returncode}: {self.proc.stderr.read().decode()}")
            try:
                requests.get(f"{self.url}/api/v1/health", timeout=2)
                return self
            except requests.RequestException:
                time.sleep(0.1)
        raise AssertionError("server did not start")

    def workers(self) -> list[int]:
        """The worker processes (spawned children, not the resource tracker)."""
        return [p for p in children(self.proc.pid) if "resource_tracker" not in cmdline(p) and alive(p)]

    def kill(self) -> list[int]:
        """SIGKILL the server; returns its workers' pids (they must die with it)."""
        workers = self.workers()
        kill9(self.proc.pid)
        self.proc.wait(30)
        return workers

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                kill9(self.proc.pid)
                self.proc.wait(10)


def submit(url: str, n: int, tag: str = "") -> list[str]:
    """n small jobs (each its own yaw, so each result is distinct); their ids."""
    ids = []
    data = glb_bytes()
    for i in range(n):
        r = requests.post(f"{url}/api/v1/jobs", data={**TINY, "yaw": str(i)},
                          files={"file": (f"cube{tag}{i}.glb", data)}, timeout=60)
        assert r.status_code == 202, r.text
        ids.append(r.json()["id"])
    return ids


@dataclass
class Outcome:
    """What became of a fault run's jobs."""

    jobs: int = 0
    kills: dict = field(default_factory=dict)
    restarts: int = 0
    done: int = 0
    failed: int = 0
    lost: int = 0  # still queued/running at the deadline ("stuck")
    duplicated: int = 0  # recorded done more than once, or listed twice
    unlogged: int = 0  # done, but no final event: its worker was killed between recording it and the log line
    deleted: int = 0  # vanished from the table
    invalid: int = 0  # done without a valid SVG, or failed without a clear message
    seconds: float = 0.0
    recovery: list = field(default_factory=list)  # seconds from a kill to the last job it affected finishing
    messages: set = field(default_factory=set)

    @property
    def clean(self) -> bool:
        return (
            not (self.lost or self.duplicated or self.deleted or self.invalid) and self.done + self.failed == self.jobs
        )


def recovery_times(hit: list, states: dict) -> list[float]:
    """Per kill: seconds from the kill to the last job that was running then being finished."""
    out = []
    for when, was_running in hit:
        ends = [states[j]["finished"] for j in was_running if states.get(j) and states[j].get("finished")]
        if ends:
            out.append(max(ends) - when)
    return out


def settle_all(url_of, ids: list[str], timeout: float) -> dict:
    """Poll until every job is done or failed (or the deadline); {id: last JSON or None if 404}."""
    end = time.monotonic() + timeout
    last: dict = {}
    while time.monotonic() < end:
        try:
            for job_id in ids:
                if last.get(job_id, {}) and last[job_id]["state"] in ("done", "failed"):
                    continue
                r = requests.get(f"{url_of()}/api/v1/jobs/{job_id}", timeout=10)
                last[job_id] = r.json() if r.status_code == 200 else None
        except requests.RequestException:
            time.sleep(0.2)
            continue
        if all(v and v["state"] in ("done", "failed") for v in last.values()) and len(last) == len(ids):
            break
        time.sleep(0.2)
    return last


def running(url: str) -> list[str]:
    """Ids of the jobs running now (empty if the server does not answer)."""
    try:
        jobs = requests.get(f"{url}/api/v1/jobs?limit=500", timeout=5).json()["jobs"]
    except requests.RequestException:
        return []
    return [j["id"] for j in jobs if j["state"] == "running"]


def wait_running(url: str, timeout: float = 120) -> None:
    """Until some job runs (a kill then hits work in progress), at most timeout seconds."""
    end = time.monotonic() + timeout
    while not running(url) and time.monotonic() < end:
        time.sleep(0.05)


def judge(url: str, ids: list[str], states: dict, storage: Path | None, out: Outcome) -> Outcome:
    """Count outcomes: valid done results, clear failures, and anything lost, duplicated or deleted."""
    listed = requests.get(f"{url}/api/v1/jobs?limit=500", timeout=10).json()["jobs"]
    listed_ids = [j["id"] for j in listed]
    out.jobs = len(ids)
    out.duplicated += len(listed_ids) - len(set(listed_ids))
    for job_id in ids:
        job = states.get(job_id)
        if job is None or job_id not in listed_ids:
            out.deleted += 1
            continue
        events = []
        if storage is not None and (storage / job_id / "events.log").is_file():
            events = [line.split()[1] for line in (storage / job_id / "events.log").read_text().splitlines()]
        finals = [e for e in events if e in ("done", "failed")]
        if job["state"] == "done":
            out.done += 1
            if storage is not None and finals and finals != ["done"]:
                out.duplicated += 1
            elif storage is not None and not finals:  # two writes (the store, then the log): a kill can fall between
                out.unlogged += 1
            svg = requests.get(f"{url}/api/v1/jobs/{job_id}/result", timeout=10).content
            try:
                if not etree.fromstring(svg).tag.endswith("svg"):
                    out.invalid += 1
            except etree.XMLSyntaxError:
                out.invalid += 1
        elif job["state"] == "failed":
            out.failed += 1
            out.messages.add(job["error"])
            if storage is not None and len(finals) > 1:
                out.duplicated += 1
            if not job["error"] or "stopped unexpectedly" not in job["error"] or "--" in job["error"]:
                out.invalid += 1
        else:
            out.lost += 1
    return out


def embedded_run(instance: Path, seed: int, n: int = 20, kills: int = 3, timeout: float = 420) -> Outcome:
    """N jobs on the embedded backend with `kills` random SIGKILLs of the server, a worker, or both."""
    rng = random.Random(seed)
    out = Outcome()
    t0 = time.monotonic()
    server = Serve(instance).wait_up()
    try:
        ids = submit(server.url, n, tag=f"s{seed}-")
        hit: list[tuple[float, list[str]]] = []  # (wall time of a kill, jobs running then)
        for _ in range(kills):
            wait_running(server.url)
            time.sleep(rng.uniform(0.0, 1.5))
            what = rng.choice(["server", "worker", "both"])
            out.kills[what] = out.kills.get(what, 0) + 1
            hit.append((time.time(), running(server.url)))
            if what in ("worker", "both"):
                workers = server.workers()
                if workers:
                    kill9(rng.choice(workers))
            if what in ("server", "both"):
                orphans = server.kill()
                end = time.monotonic() + 10
                while any(alive(p) for p in orphans) and time.monotonic() < end:
                    time.sleep(0.05)
                assert not any(alive(p) for p in orphans), "workers outlived their server"
                server = Serve(instance).wait_up()
                out.restarts += 1
        states = settle_all(lambda: server.url, ids, timeout)
        out.recovery += recovery_times(hit, states)
        judge(server.url, ids, states, instance / "jobs", out)
    finally:
        server.stop()
    out.seconds = time.monotonic() - t0
    return out


def table(instance: Path) -> dict:
    """{id: (state, owner, attempts)} read straight from the embedded job table."""
    from webapp.jobstore import SQLiteStore

    store = SQLiteStore(instance / "jobs.sqlite3")
    try:
        return {j.id: (j.state, j.owner, j.attempts) for j in store.recent(1000)}
    finally:
        store.close()


def second_serve_run(instance: Path, n: int = 20, timeout: float = 420) -> tuple[Outcome, int, str, dict, dict]:
    """A second `facesvg serve` on a live server's folder: its exit code and stderr, the table before/after."""
    out = Outcome()
    t0 = time.monotonic()
    server = Serve(instance).wait_up()
    try:
        ids = submit(server.url, n, tag="second-")
        end = time.monotonic() + 60
        while not running(server.url) and time.monotonic() < end:
            time.sleep(0.05)
        before = table(instance)
        second = Serve(instance)
        code = second.proc.wait(60)
        err = second.proc.stderr.read().decode()
        after = table(instance)
        states = settle_all(lambda: server.url, ids, timeout)
        judge(server.url, ids, states, instance / "jobs", out)
    finally:
        server.stop()
    out.seconds = time.monotonic() - t0
    return out, code, err, before, after


class RQWorker:
    """`facesvg worker` on the Redis queue (its work horse is forked per job)."""

    def __init__(self, redis_url: str, log: Path, env: dict | None = None) -> None:
        # its output goes to log (appended: a replacement worker writes after the one it replaces), kept for the
        # post-mortem of a run that loses a job
        with open(log, "ab") as out:
            self.proc = subprocess.Popen([sys.executable, "-m", "converter.cli", "worker", "--queue", redis_url],
                                         cwd=ROOT, env={**os.environ, **FAST_ENV, **(env or {})}, stdout=out,
                                         stderr=subprocess.STDOUT)

    def horses(self) -> list[int]:
        return [p for p in children(self.proc.pid) if alive(p)]

    def stop(self) -> None:
        if self.proc.poll() is None:
            kill9(self.proc.pid)
            self.proc.wait(10)


def rq_run(instance: Path, redis_url: str, seed: int, n: int = 20, kills: int = 3,
           timeout: float = 420) -> Outcome:
    """N jobs on the RQ backend with random SIGKILLs of a worker or of its work horse; a fresh worker replaces it."""
    import redis

    redis.Redis.from_url(redis_url).flushdb()
    rng = random.Random(seed)
    out = Outcome()
    t0 = time.monotonic()
    server = Serve(instance, queue=redis_url).wait_up()
    logs = [instance.parent / f"rq-worker-{i}.log" for i in range(2)]  # beside the instance, which Serve makes
    workers = [RQWorker(redis_url, log) for log in logs]
    try:
        ids = submit(server.url, n, tag=f"rq{seed}-")
        hit = []
        for _ in range(kills):
            wait_running(server.url)
            time.sleep(rng.uniform(0.0, 1.5))
            what = rng.choice(["worker", "horse"])
            out.kills[what] = out.kills.get(what, 0) + 1
            hit.append((time.time(), running(server.url)))
            victim = rng.choice(workers)
            if what == "horse" and victim.horses():
                kill9(rng.choice(victim.horses()))
            else:
                horses = victim.horses()
                victim.stop()
                end = time.monotonic() + 10
                while any(alive(p) for p in horses) and time.monotonic() < end:
                    time.sleep(0.05)
                assert not any(alive(p) for p in horses), "a work horse outlived its worker"
                slot = workers.index(victim)
                workers[slot] = RQWorker(redis_url, logs[slot])
                out.restarts += 1
        states = settle_all(lambda: server.url, ids, timeout)
        out.recovery += recovery_times(hit, states)
        judge(server.url, ids, states, instance / "jobs", out)
    finally:
        for w in workers:
            w.stop()
        server.stop()
    out.seconds = time.monotonic() - t0
    return out


def oversized_post(port: int, size: int, chunked: bool = False) -> tuple[bytes, int]:
    """Send a body of size bytes (declared, or chunked without a length) until the server answers;
    (answer, body bytes sent)."""
    length = "Transfer-Encoding: chunked" if chunked else f"Content-Length: {size}"
    head = (f"POST /api/v1/jobs HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n{length}\r\n"
            "Content-Type: multipart/form-data; boundary=x\r\n\r\n").encode()
    sent = 0
    answer = b""
    chunk = b"\0" * 65536
    if chunked:
        chunk = b"10000\r\n" + chunk + b"\r\n"  # 0x10000 = 65536 bytes per chunk
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(head)
        s.settimeout(0.05)
        while sent < size:
            try:
                answer += s.recv(4096)
                if answer:
                    break
            except (TimeoutError, BlockingIOError):
                pass
            try:
                s.sendall(chunk)
                sent += 65536
            except (BrokenPipeError, ConnectionResetError):
                break
        s.settimeout(5)
        try:
            answer += s.recv(4096)
        except OSError:
            pass
    return answer, sent
