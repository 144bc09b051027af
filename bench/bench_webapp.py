"""Web UI figures (issue 5): submission and polling requests/s, end-to-end seconds, server memory under load."""

from __future__ import annotations

import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

TITLE = "Web UI: requests/s, end-to-end seconds, server memory (issue 5)"
ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out" / "webapp"
SAMPLE = ROOT / "samples" / "face.glb"
CLIENTS = 4  # concurrent HTTP clients for the request-rate figures
SUBMISSIONS = 120
POLLS = 2000
E2E_REPEATS = 3
CONCURRENT_JOBS = 20
TINY = {"size": "64", "occlusion": "0", "end": "2"}  # submissions measured, not their conversions
LOAD_OPTIONS = {"size": "256", "end": "40"}  # the memory figure's jobs: 40 of the sample's frames, occlusion on


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """`facesvg serve` in a subprocess with a fresh instance folder (the real production entry point)."""

    def __init__(self, name: str, workers: int = 2, queue: str | None = None) -> None:
        import requests

        self.instance = OUT / name
        shutil.rmtree(self.instance, ignore_errors=True)
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        cmd = [sys.executable, "-m", "converter.cli", "serve", "--port", str(self.port), "--workers", str(workers),
               "--instance", str(self.instance)]
        if queue:
            cmd += ["--queue", queue]
        # The submission-rate figures measure the server, not its per-client limits (issue 17): both off.
        env = dict(os.environ, PYOPENGL_PLATFORM="egl", FACESVG_SAMPLE=str(SAMPLE), FACESVG_RATE_LIMIT="0",
                   FACESVG_QUEUE_CAP="0")
        self.proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(200):
            try:
                requests.get(self.url + "/api/v1/health", timeout=1)
                return
            except requests.ConnectionError:
                time.sleep(0.1)
        raise RuntimeError("server did not start")

    def rss_mb(self) -> tuple[float, float]:
        """Resident memory of the server process alone and with all its worker processes, MB."""
        own = _rss_kb(self.proc.pid)
        total = own + sum(_rss_kb(p) for p in _descendants(self.proc.pid))
        return own / 1024, total / 1024

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def _rss_kb(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = [int(x) for x in (task / "children").read_text().split()]
            except OSError:
                kids = []
            out += kids
            todo += kids
    return out


def _rate(n: int, work) -> float:
    """Requests per second of n calls of work(session, i) spread over CLIENTS threads."""
    import requests

    per = n // CLIENTS

    def client(k: int) -> None:
        with requests.Session() as s:
            for i in range(per):
                work(s, k * per + i)

    threads = [threading.Thread(target=client, args=(k,)) for k in range(CLIENTS)]
    t = time.perf_counter()
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return per * CLIENTS / (time.perf_counter() - t)


def _wait(session, url: str, job_id: str, timeout: float = 600) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        job = session.get(f"{url}/api/v1/jobs/{job_id}", timeout=30).json()
        if job["state"] in ("done", "failed"):
            return job
        time.sleep(0.05)
    raise RuntimeError(f"job {job_id} timed out")


def request_rates(server: Server, glb: bytes) -> dict:
    """Submission and status-poll rates against one server."""
    import requests

    ids: list[str] = []

    def submit(s, i):
        r = s.post(server.url + "/api/v1/jobs", data=TINY, files={"file": ("cube.glb", glb)}, timeout=60)
        r.raise_for_status()
        ids.append(r.json()["id"])

    submit_rate = _rate(SUBMISSIONS, submit)
    with requests.Session() as s:
        for job_id in ids:  # drop the backlog (queued jobs are cancelled) so it does not skew later figures
            s.delete(f"{server.url}/api/v1/jobs/{job_id}", timeout=30)
        done = s.post(server.url + "/api/v1/jobs", data=TINY, files={"file": ("cube.glb", glb)}, timeout=60).json()
        job_id = _wait(s, server.url, done["id"])["id"]
    poll_rate = _rate(POLLS, lambda s, i: s.get(f"{server.url}/api/v1/jobs/{job_id}", timeout=30).raise_for_status())
    return {"submit": submit_rate, "poll": poll_rate}


def end_to_end(server: Server) -> list[float]:
    """Seconds from the sample's upload to its SVG downloaded, default options, one job at a time."""
    import requests

    data = SAMPLE.read_bytes()
    times = []
    with requests.Session() as s:
        for _ in range(E2E_REPEATS):
            t = time.perf_counter()
            r = s.post(server.url + "/api/v1/jobs", files={"file": ("face.glb", data)}, timeout=60).json()
            job = _wait(s, server.url, r["id"])
            assert job["state"] == "done", job["error"]
            svg = s.get(server.url + job["links"]["result"], timeout=60).content
            times.append(time.perf_counter() - t)
            assert svg.startswith(b"<")
    return times


def cli_seconds() -> list[float]:
    """The same conversion by `facesvg convert` (baseline: no web, no prerender previews)."""
    times = []
    out = Path(tempfile.mkdtemp(dir=OUT)) / "face.svg"
    for _ in range(E2E_REPEATS):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "converter.cli", "convert", str(SAMPLE), "-o", str(out), "-q"],
                       cwd=ROOT, check=True, env=dict(os.environ, PYOPENGL_PLATFORM="egl"), capture_output=True)
        times.append(time.perf_counter() - t)
    return times


def memory_under_load(server: Server) -> dict:
    """Peak RSS while CONCURRENT_JOBS sample jobs (LOAD_OPTIONS) are submitted at once and run."""
    import requests

    data = SAMPLE.read_bytes()
    idle = server.rss_mb()
    ids: list[str] = []
    peak = [0.0, 0.0]
    stop = threading.Event()

    def sample_rss():
        while not stop.is_set():
            own, total = server.rss_mb()
            peak[0], peak[1] = max(peak[0], own), max(peak[1], total)
            time.sleep(0.1)

    def submit(i):
        r = requests.post(server.url + "/api/v1/jobs", data=LOAD_OPTIONS, files={"file": ("face.glb", data)},
                          timeout=120)
        ids.append(r.json()["id"])

    watcher = threading.Thread(target=sample_rss)
    watcher.start()
    t = time.perf_counter()
    threads = [threading.Thread(target=submit, args=(i,)) for i in range(CONCURRENT_JOBS)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    with requests.Session() as s:
        states = [_wait(s, server.url, i)["state"] for i in ids]
    elapsed = time.perf_counter() - t
    stop.set()
    watcher.join()
    return {"idle": idle, "peak_own": peak[0], "peak_total": peak[1], "done": states.count("done"),
            "jobs": len(ids), "seconds": elapsed}


def _redis():
    """A throwaway redis-server and one `facesvg worker`, if redis-server is installed."""
    exe = shutil.which("redis-server")
    if not exe:
        return None
    port = _free_port()
    redis_proc = subprocess.Popen([exe, "--port", str(port), "--bind", "127.0.0.1", "--save", ""],
                                  stdout=subprocess.DEVNULL)
    url = f"redis://127.0.0.1:{port}/0"
    time.sleep(0.5)
    worker = subprocess.Popen([sys.executable, "-m", "converter.cli", "worker", "--queue", url], cwd=ROOT,
                              env=dict(os.environ, PYOPENGL_PLATFORM="egl"), stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    return url, [worker, redis_proc]


def run() -> str:
    sys.path.insert(0, str(ROOT / "tests"))
    from web.conftest import glb_bytes

    OUT.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()[0]
    glb = glb_bytes()
    rows = []
    server = Server("embedded", workers=2)
    try:
        rates = {"embedded": request_rates(server, glb)}
        e2e = end_to_end(server)
        mem = memory_under_load(server)
    finally:
        server.close()
    cli = cli_seconds()
    rq = _redis()
    if rq:
        url, procs = rq
        server = Server("rq", queue=url)
        try:
            rates["rq"] = request_rates(server, glb)
        finally:
            server.close()
            for p in procs:
                p.terminate()
                p.wait(20)
    load_after = os.getloadavg()[0]
    for name, r in rates.items():
        rows.append(f"| {name} | {r['submit']:.0f} | {r['poll']:.0f} |")
    return "\n".join([
        f"Server: `facesvg serve` (waitress, 8 threads) in its own process on 127.0.0.1, {CLIENTS} concurrent "
        "`requests` clients; the embedded backend runs 2 worker processes; the RQ backend one `facesvg worker`. "
        f"The 2-core machine is shared (1-minute load average {load_before:.1f} at the start, {load_after:.1f} at "
        "the end), so times vary run to run.",
        "",
        "| backend | job submissions/s (multipart upload of a 1 KB glTF) | status polls/s (GET /api/v1/jobs/ID) |",
        "|---|---|---|",
        *rows,
        "",
        f"{SUBMISSIONS} submissions and {POLLS} polls per figure; submitted jobs queue behind real background "
        "work, as in use (their backlog is cancelled with DELETE afterwards).",
        "",
        "| bundled sample (`samples/face.glb`, 121 frames, 2,998 triangles, default options: 512 px, occlusion on) "
        "| median s | runs |",
        "|---|---|---|",
        f"| web: upload -> SVG downloaded (incl. verification and 48 prerender PNGs) | {statistics.median(e2e):.2f} | "
        f"{', '.join(f'{x:.2f}' for x in e2e)} |",
        f"| baseline: `facesvg convert` process (start to file written) | {statistics.median(cli):.2f} | "
        f"{', '.join(f'{x:.2f}' for x in cli)} |",
        "",
        f"| memory, {mem['jobs']} sample jobs (256 px, frames 0-39) submitted at once | MB |",
        "|---|---|",
        f"| server process idle (after the runs above) | {mem['idle'][0]:.0f} |",
        f"| server process peak | {mem['peak_own']:.0f} |",
        f"| server + 2 worker processes peak | {mem['peak_total']:.0f} |",
        f"| jobs done / submitted; seconds until all finished | {mem['done']}/{mem['jobs']}; {mem['seconds']:.1f} s |",
    ])
