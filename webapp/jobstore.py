"""The job table: one record per job, in SQLite (embedded backend) or in Redis (RQ backend)."""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

QUEUED, RUNNING, DONE, FAILED, CANCELLING, CANCELLED = "queued", "running", "done", "failed", "cancelling", "cancelled"
FINISHED = (DONE, FAILED, CANCELLED)


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
JSON_COLUMNS = ("options", "files", "result", "progress_origin")


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
                "client TEXT DEFAULT '', progress_origin TEXT DEFAULT '{}')"
            )
            have = {r[1] for r in db.execute("PRAGMA table_info(jobs)")}
            for column, decl in (("owner", "TEXT DEFAULT ''"), ("lease", "REAL DEFAULT 0"),
                                 ("client", "TEXT DEFAULT ''"), ("progress_origin", "TEXT DEFAULT '{}'")):
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
            self._local.conn = conn
            with self._all_lock:
                self._all.append(conn)
        return conn

    @staticmethod
    def _encode(key: str, value):
        return json.dumps(value) if key in JSON_COLUMNS else value

    @staticmethod
    def _job(row: sqlite3.Row) -> Job:
        data = {k: row[k] for k in COLUMNS}
        for k in JSON_COLUMNS:
            data[k] = json.loads(data[k] or "{}")
        data["owner"], data["lease"], data["client"] = data["owner"] or "", data["lease"] or 0.0, data["client"] or ""
        return Job(**data)

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
        data = {k: json.dumps(v) for k, v in job.to_json().items()}
        pipe = self.redis.pipeline()
        pipe.hset(self._key(job.id), mapping=data)
        pipe.zadd(self._index, {job.id: job.created})
        pipe.execute()

    def get(self, job_id: str) -> Job | None:
        raw = self.redis.hgetall(self._key(job_id))
        if not raw:
            return None
        return Job(**{k.decode(): json.loads(v) for k, v in raw.items() if k.decode() in COLUMNS})

    def _many(self, ids) -> list[Job]:
        pipe = self.redis.pipeline()
        for i in ids:
            pipe.hgetall(self._key(i.decode() if isinstance(i, bytes) else i))
        out = []
        for raw in pipe.execute():
            if raw:
                out.append(Job(**{k.decode(): json.loads(v) for k, v in raw.items() if k.decode() in COLUMNS}))
        return out

    def recent(self, limit: int = 50) -> list[Job]:
        return self._many(self.redis.zrevrange(self._index, 0, int(limit) - 1))

    def transition(self, job_id: str, from_states: tuple[str, ...], holder: str | None = None, **changes) -> bool:
        bad = set(changes) - set(COLUMNS)
        if bad:
            raise KeyError(f"unknown job fields {sorted(bad)}")
        args = ["" if holder is None else json.dumps(holder), len(from_states), *(json.dumps(s) for s in from_states)]
        for k, v in changes.items():
            args += [k, json.dumps(v)]
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
