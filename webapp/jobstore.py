"""The job table: one record per job, in SQLite (embedded backend) or in Redis (RQ backend)."""

from __future__ import annotations

import json
import logging
import math
import sqlite3
import threading
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from webapp import strictjson

log = logging.getLogger("facesvg.webapp")

QUEUED, RUNNING, DONE, FAILED, CANCELLING, CANCELLED = "queued", "running", "done", "failed", "cancelling", "cancelled"
FINISHED = (DONE, FAILED, CANCELLED)
STATES = (QUEUED, RUNNING, DONE, FAILED, CANCELLING, CANCELLED)
DAMAGED = "damaged"  # the stage shown for a record that could not be read back (shown as failed)


@dataclass
class Job:
    """One conversion job: its state, progress, inputs (generated file names) and result summary."""

    id: str
    state: str = QUEUED
    stage: str = "queued"
    progress: float = 0.0
    message: str = ""
    filename: str = ""  # the uploaded name, for display only (never used as a path)
    kind: str = ""  # sniffed input kind
    options: dict = field(default_factory=dict)  # scalar ConversionOptions fields as submitted
    files: dict = field(default_factory=dict)  # role (input, cache, fap, ...) -> generated stored name
    names: dict = field(default_factory=dict)  # role -> the user's file name of that upload (display only)
    created: float = 0.0
    started: float | None = None
    finished: float | None = None
    attempts: int = 0
    result: dict = field(default_factory=dict)  # report, frames, fps, preview frames, output kinds
    owner: str = ""  # the worker holding the job while running (empty otherwise)
    lease: float = 0.0  # the holder's claim expires at this time unless renewed (heartbeat)
    client: str = ""  # who submitted it (API key id or browser session id; empty when keys are off)
    progress_origin: dict = field(default_factory=dict)  # {"time", "progress"} where the input had been read: the
    # running attempt's ETA counts from there (converter.options.Eta)

    def to_json(self) -> dict:
        """Plain dict of the record."""
        return asdict(self)


COLUMNS = tuple(f.name for f in fields(Job))
JSON_COLUMNS = ("options", "files", "names", "result", "progress_origin")
TEXT_COLUMNS = ("id", "state", "stage", "message", "filename", "kind", "owner", "client")
NUMBER_COLUMNS = {"progress": 0.0, "created": 0.0, "started": None, "finished": None, "lease": 0.0}


def encode_json(value: Any) -> str:
    """A JSON column as stored: strict JSON, every non-finite number written as null."""
    return strictjson.dumps(value)


def damaged(job: Job, why: str) -> Job:
    """The view of a job whose stored record (or result) cannot be used: failed, with what to do."""
    return replace(job, state=FAILED, stage=DAMAGED, progress=0.0, result={},
                   message=f"the stored record of this job is damaged ({why}); delete the job and convert the file "
                           "again.")


def is_damaged(job: Job) -> bool:
    """True for the view made by damaged()."""
    return job.state == FAILED and job.stage == DAMAGED


def job_from_record(raw: dict[str, Any], job_id: str) -> Job:
    """A Job from stored column values (JSON columns still as text); a garbled record reads as a damaged job.

    Non-finite numbers (records written before the store refused them) read as None; one bad record never
    raises, so it cannot break a list of jobs or another job's page.
    """
    data: dict[str, Any] = {"id": job_id}
    problems = []
    for name in COLUMNS:
        value = raw.get(name)
        if name in JSON_COLUMNS:
            try:
                value = strictjson.loads(value) if value else {}
            except (ValueError, TypeError, RecursionError):
                problems.append(f"{name} is not JSON")
                value = {}
            if not isinstance(value, dict):
                problems.append(f"{name} is not an object")
                value = {}
        elif name in TEXT_COLUMNS:
            if value is None:
                value = job_id if name == "id" else ""
            elif not isinstance(value, str):
                problems.append(f"{name} is not text")
                value = str(value)
        elif name in NUMBER_COLUMNS:
            value = _number(value, NUMBER_COLUMNS[name], problems, name)
        elif name == "attempts":
            number = _number(value, 0, problems, name)
            value = int(number) if number is not None else 0
        data[name] = value
    if data["state"] not in STATES:
        problems.append(f"unknown state {data['state'][:20]!r}")
        data["state"] = FAILED
    if data["state"] == DONE:
        problems += result_problems(data["result"])
    origin = data["progress_origin"]
    if origin and not all(isinstance(origin.get(k), (int, float)) for k in ("time", "progress")):
        data["progress_origin"] = {}  # only the ETA reads it: it falls back to the elapsed time
    job = Job(**data)
    if problems:
        log.warning("job %s: damaged record: %s", job_id, "; ".join(problems))
        return damaged(job, "; ".join(problems))
    return job


def result_problems(result: dict) -> list[str]:
    """What makes a finished job's result summary unusable by the pages and the API (empty when it is fine)."""
    problems = []
    frames = result.get("preview_frames", [])
    if not isinstance(frames, list) or not all(isinstance(k, int) and not isinstance(k, bool) for k in frames):
        problems.append("result.preview_frames is not a list of frames")
    for key in ("frames", "still"):
        if result.get(key) is not None and (not isinstance(result[key], int) or isinstance(result[key], bool)):
            problems.append(f"result.{key} is not a whole number")
    for key in ("fps", "duration", "size"):
        if result.get(key) is not None and (not isinstance(result[key], (int, float)) or isinstance(result[key], bool)):
            problems.append(f"result.{key} is not a number")
    for key in ("outputs", "report"):
        if not isinstance(result.get(key, {}), dict):
            problems.append(f"result.{key} is not an object")
    report = result.get("report")
    if isinstance(report, dict):
        problems += [f"result.report.{key} is not an object" for key in ("counts", "figures", "sizes")
                     if not isinstance(report.get(key, {}), dict)]
    return problems


def _number(value: Any, default: float | None, problems: list[str], name: str) -> float | None:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{name} is not a number")
        return default
    return float(value) if math.isfinite(value) else default


class JobStore:
    """Interface of a job table; every state change is a conditional transition so races resolve safely."""

    url: str

    def add(self, job: Job) -> None:
        """Insert a new record."""
        raise NotImplementedError

    def get(self, job_id: str) -> Job | None:
        """The record, or None."""
        raise NotImplementedError

    def recent(self, limit: int = 50) -> list[Job]:
        """The newest records first."""
        raise NotImplementedError

    def transition(self, job_id: str, from_states: tuple[str, ...], holder: str | None = None, **changes) -> bool:
        """Apply changes only if the job's state is one of from_states (and, given holder, its owner is holder)."""
        raise NotImplementedError

    def remove(self, job_id: str) -> None:
        """Delete the record."""
        raise NotImplementedError

    def with_state(self, states: tuple[str, ...]) -> list[Job]:
        """Records in any of the states, oldest first."""
        raise NotImplementedError

    def claim(self, job_id: str, owner: str = "", lease_seconds: float = 60.0) -> bool:
        """Atomically move a queued job to running, held by owner until the lease expires; False if not queued."""
        job = self.get(job_id)
        if job is None or job.state != QUEUED:
            return False
        now = time.time()
        return self.transition(job_id, (QUEUED,), state=RUNNING, stage="starting", started=now,
                               attempts=job.attempts + 1, owner=owner, lease=now + lease_seconds,
                               progress_origin={})

    def claim_next(self, owner: str, lease_seconds: float) -> str | None:
        """Claim the oldest queued job for owner; its id, or None when nothing is queued."""
        for job in self.with_state((QUEUED,)):
            if self.claim(job.id, owner, lease_seconds):
                return job.id
        return None

    def count_active(self) -> int:
        """How many jobs are queued or running."""
        return len(self.with_state((QUEUED, RUNNING)))

    def finished_before(self, cutoff: float) -> list[str]:
        """Ids of finished jobs older than cutoff (seconds since the epoch)."""
        return [j.id for j in self.with_state(FINISHED) if (j.finished or j.created) < cutoff]

    def close(self) -> None:
        """Release connections."""


class SQLiteStore(JobStore):
    """The job table in one SQLite file (WAL mode; one connection per thread; safe across processes)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.url = f"sqlite:///{self.path}"
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._all_lock = threading.Lock()
        with self._conn() as db:
            db.execute(
                "CREATE TABLE IF NOT EXISTS jobs (id TEXT PRIMARY KEY, state TEXT, stage TEXT, progress REAL, "
                "message TEXT, filename TEXT, kind TEXT, options TEXT, files TEXT, created REAL, started REAL, "
                "finished REAL, attempts INTEGER, result TEXT, owner TEXT DEFAULT '', lease REAL DEFAULT 0, "
                "client TEXT DEFAULT '', progress_origin TEXT DEFAULT '{}', names TEXT DEFAULT '{}')"
            )
            have = {r[1] for r in db.execute("PRAGMA table_info(jobs)")}
            for column, decl in (("owner", "TEXT DEFAULT ''"), ("lease", "REAL DEFAULT 0"),
                                 ("client", "TEXT DEFAULT ''"), ("progress_origin", "TEXT DEFAULT '{}'"),
                                 ("names", "TEXT DEFAULT '{}'")):
                if column not in have:  # a table written before these existed
                    db.execute(f"ALTER TABLE jobs ADD COLUMN {column} {decl}")
            db.execute("CREATE INDEX IF NOT EXISTS jobs_created ON jobs (created)")
            db.execute("CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state)")

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, timeout=30, isolation_level=None, check_same_thread=False)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.row_factory = sqlite3.Row
            conn.text_factory = _lenient_text  # one row with broken text must not make a whole list unreadable
            self._local.conn = conn
            with self._all_lock:
                self._all.append(conn)
        return conn

    @staticmethod
    def _encode(key: str, value):
        if key in JSON_COLUMNS:
            return encode_json(value)
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    @staticmethod
    def _job(row: sqlite3.Row) -> Job:
        return job_from_record({k: row[k] for k in row.keys()}, str(row["id"]))

    def add(self, job: Job) -> None:
        data = job.to_json()
        self._conn().execute(
            f"INSERT INTO jobs ({', '.join(COLUMNS)}) VALUES ({', '.join('?' * len(COLUMNS))})",
            [self._encode(k, data[k]) for k in COLUMNS],
        )

    def get(self, job_id: str) -> Job | None:
        row = self._conn().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return self._job(row) if row else None

    def recent(self, limit: int = 50) -> list[Job]:
        rows = self._conn().execute("SELECT * FROM jobs ORDER BY created DESC LIMIT ?", (int(limit),)).fetchall()
        return [self._job(r) for r in rows]

    def transition(self, job_id: str, from_states: tuple[str, ...], holder: str | None = None, **changes) -> bool:
        bad = set(changes) - set(COLUMNS)
        if bad:
            raise KeyError(f"unknown job fields {sorted(bad)}")
        sets = ", ".join(f"{k} = ?" for k in changes)
        marks = ", ".join("?" * len(from_states))
        owned = "" if holder is None else " AND owner = ?"
        cur = self._conn().execute(
            f"UPDATE jobs SET {sets} WHERE id = ? AND state IN ({marks}){owned}",
            [self._encode(k, v) for k, v in changes.items()] + [job_id, *from_states]
            + ([] if holder is None else [holder]),
        )
        return cur.rowcount == 1

    def claim_next(self, owner: str, lease_seconds: float) -> str | None:
        now = time.time()
        row = self._conn().execute(
            "UPDATE jobs SET state = ?, stage = 'starting', started = ?, attempts = attempts + 1, owner = ?, "
            "lease = ?, progress_origin = '{}' "
            "WHERE id = (SELECT id FROM jobs WHERE state = ? ORDER BY created LIMIT 1) AND state = ? "
            "RETURNING id", (RUNNING, now, owner, now + lease_seconds, QUEUED, QUEUED)).fetchall()
        return row[0][0] if row else None

    def count_active(self) -> int:
        return int(self._conn().execute("SELECT COUNT(*) FROM jobs WHERE state IN (?, ?)",
                                        (QUEUED, RUNNING)).fetchone()[0])

    def remove(self, job_id: str) -> None:
        self._conn().execute("DELETE FROM jobs WHERE id = ?", (job_id,))

    def with_state(self, states: tuple[str, ...]) -> list[Job]:
        marks = ", ".join("?" * len(states))
        rows = self._conn().execute(f"SELECT * FROM jobs WHERE state IN ({marks}) ORDER BY created", states).fetchall()
        return [self._job(r) for r in rows]

    def close(self) -> None:
        with self._all_lock:
            conns, self._all = self._all, []
        for conn in conns:
            conn.close()
        self._local = threading.local()


def _lenient_text(data: bytes) -> str:
    return data.decode("utf-8", errors="replace")


# Compare-and-set on a hash field: KEYS[1] = job hash; ARGV = required owner ('' = any), n, n allowed states,
# then field/value pairs (values JSON-encoded, as stored).
_TRANSITION_LUA = """
local s = redis.call('HGET', KEYS[1], 'state')
if not s then return 0 end
if ARGV[1] ~= '' and redis.call('HGET', KEYS[1], 'owner') ~= ARGV[1] then return 0 end
table.remove(ARGV, 1)
local n = tonumber(ARGV[1])
for i = 2, n + 1 do
  if ARGV[i] == s then
    for j = n + 2, #ARGV, 2 do redis.call('HSET', KEYS[1], ARGV[j], ARGV[j + 1]) end
    return 1
  end
end
return 0
"""


class RedisStore(JobStore):
    """The job table in Redis: a hash per job (JSON-encoded fields) and a sorted set ordered by creation."""

    def __init__(self, url: str, prefix: str = "facesvg") -> None:
        import redis  # noqa: PLC0415 - the Redis backend is optional; loaded only when configured

        self.url = url
        self.prefix = prefix
        self.redis = redis.Redis.from_url(url)
        self._transition = self.redis.register_script(_TRANSITION_LUA)

    def _key(self, job_id: str) -> str:
        return f"{self.prefix}:job:{job_id}"

    @property
    def _index(self) -> str:
        return f"{self.prefix}:jobs"

    def add(self, job: Job) -> None:
        data = {k: encode_json(v) for k, v in job.to_json().items()}
        pipe = self.redis.pipeline()
        pipe.hset(self._key(job.id), mapping=data)
        pipe.zadd(self._index, {job.id: job.created})
        pipe.execute()

    def get(self, job_id: str) -> Job | None:
        raw = self.redis.hgetall(self._key(job_id))
        return self._job(raw, job_id) if raw else None

    @staticmethod
    def _job(raw: dict, job_id: str) -> Job:
        """A Job from a hash of JSON-encoded fields (every field but the JSON columns decoded here)."""
        values: dict[str, Any] = {}
        bad = []
        for key, value in raw.items():
            name = key.decode("utf-8", errors="replace")
            if name not in COLUMNS:
                continue
            text = value.decode("utf-8", errors="replace")
            if name in JSON_COLUMNS:
                values[name] = text
                continue
            try:
                values[name] = strictjson.loads(text)
            except (ValueError, RecursionError):
                bad.append(name)
                values[name] = None
        job = job_from_record(values, job_id)
        return damaged(job, ", ".join(bad) + " not JSON") if bad and not is_damaged(job) else job

    def _many(self, ids) -> list[Job]:
        names = [i.decode() if isinstance(i, bytes) else i for i in ids]
        pipe = self.redis.pipeline()
        for i in names:
            pipe.hgetall(self._key(i))
        return [self._job(raw, i) for i, raw in zip(names, pipe.execute()) if raw]

    def recent(self, limit: int = 50) -> list[Job]:
        return self._many(self.redis.zrevrange(self._index, 0, int(limit) - 1))

    def transition(self, job_id: str, from_states: tuple[str, ...], holder: str | None = None, **changes) -> bool:
        bad = set(changes) - set(COLUMNS)
        if bad:
            raise KeyError(f"unknown job fields {sorted(bad)}")
        args = ["" if holder is None else json.dumps(holder), len(from_states), *(json.dumps(s) for s in from_states)]
        for k, v in changes.items():
            args += [k, encode_json(v)]
        return bool(self._transition(keys=[self._key(job_id)], args=args))

    def remove(self, job_id: str) -> None:
        pipe = self.redis.pipeline()
        pipe.delete(self._key(job_id))
        pipe.zrem(self._index, job_id)
        pipe.execute()

    def with_state(self, states: tuple[str, ...]) -> list[Job]:
        return [j for j in self._many(self.redis.zrange(self._index, 0, -1)) if j.state in states]

    def close(self) -> None:
        self.redis.close()


def open_store(url: str) -> JobStore:
    """The store named by a URL: sqlite:///path or redis://host:port/db."""
    if url.startswith("sqlite:///"):
        return SQLiteStore(url[len("sqlite:///"):])
    if url.startswith(("redis://", "rediss://", "unix://")):
        return RedisStore(url)
    raise ValueError(f"unknown job store URL {url!r}")
