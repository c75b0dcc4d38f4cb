"""The durable job store: every job the fleet manager accepted and every change of its state, in an
embedded SQLite database (stdlib :mod:`sqlite3`, write-ahead log), so that a planner killed at any
moment and started again on the same file knows every accepted job and how far it had got
(docs/ARCHITECTURE.md, "Where each concept lives": job store under ``fleet/``).

Each change is one transaction, committed before the call returns (``synchronous=FULL``: on disk,
not only in the operating system's cache), and the manager announces a change only after the call
returned: an event seen on the wire is in the store. Tables:

* ``jobs`` - one row per accepted task: its JSON (``fleet/task@1``), its submission order, its
  state (queued | active | done | failed), the robot on it, whether its goods were picked;
* ``transitions`` - one row per change: the job, the event (accepted, assigned, picked, placed,
  done, failed, requeued, reloaded), state, robot, picked, stamp and reason;
* ``outbox`` - one row: the number of the last transition whose task events reached their
  subscribers (the publisher says so, :meth:`JobStore.mark_announced`: the planner node once every
  matched subscriber acknowledged them, not when it handed them to the middleware). A change
  committed and not yet announced when the planner died (killed in the middle of a step: committed,
  not yet published; or published, and lost with the planner before the middleware's reliability
  repaired a lost sample) is announced by the next planner on the file (:meth:`JobStore.unannounced`):
  events are at least once across a restart, never lost; a replay repeats the original's stamp, so a
  subscriber can tell it.
"""
from __future__ import annotations

import fcntl
import os
import sqlite3
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, cast

from msg_schemas.records import Task

#: the states a job is finished in (never reloaded)
CLOSED = ("done", "failed", "cancelled")
#: how the answer to a task whose id is known already begins its reason: the event is the job's
#: current state (:func:`current_event`), not news (``fleet-submit`` reads it so)
RESENT = "re-sent task id: the job's state now"


#: the planner's ``job_store`` setting that keeps jobs in memory only (nothing survives a restart)
MEMORY = ":memory:"
#: where the planner keeps its jobs by default: this file under the ROS home, per fleet
DEFAULT_FILE = "jobs.sqlite"


def default_path(env: Mapping[str, str] | None = None, namespace: str = "/") -> Path:
    """The default job store of the planner in ``namespace``:
    ``$ROS_HOME/fleet_planner/domain_<ROS_DOMAIN_ID>/<namespace>/jobs.sqlite`` (ROS_HOME unset or
    empty: ``~/.ros``, as ROS 2 reads it; no domain id: 0). One file per fleet: two fleets on one
    machine (another domain, another namespace) never share their jobs."""
    env = os.environ if env is None else env
    home = env.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    domain = env.get("ROS_DOMAIN_ID", "").strip()
    parts = [p for p in namespace.split("/") if p]
    return Path(home, "fleet_planner", f"domain_{int(domain) if domain.isdigit() else 0}", *parts, DEFAULT_FILE)


def open_store(setting: str, env: Mapping[str, str] | None = None, namespace: str = "/",
               lock: bool = False) -> JobStore | None:
    """The job store a ``job_store`` setting names: empty, the default file of the fleet in
    ``namespace`` (:func:`default_path`); :data:`MEMORY`, none (jobs in memory only); else that
    file. Created, with its folders, if missing; with ``lock``, held for this process alone (see
    :class:`JobStore`). ValueError naming the setting if it cannot be opened."""
    if setting == MEMORY:
        return None
    path = Path(os.path.expanduser(setting)) if setting else default_path(env, namespace)
    try:
        return JobStore(path, lock=lock)
    except (OSError, sqlite3.Error) as exc:
        raise ValueError(f"job_store: cannot open {str(path)!r} ({exc})") from None


def emptied(path: str | Path) -> Path:
    """``path`` with no job store left there (the SQLite file and its write-ahead log removed): a
    run whose job ids repeat those of the last run starts from nothing."""
    path = Path(path)
    for old in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        old.unlink(missing_ok=True)
    return path


def current_event(state: str, picked: bool) -> str:
    """The task event that tells a job's ``state`` to a client sending its id again: ``accepted``
    (queued), ``assigned`` or ``picked`` (active: on its robot, before or after the pick), ``done``,
    ``failed`` or ``cancelled``: what the planner last said about the job."""
    if state == "queued":
        return "accepted"
    if state == "active":
        return "picked" if picked else "assigned"
    return state

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    task TEXT NOT NULL,
    seq INTEGER NOT NULL,
    state TEXT NOT NULL,
    robot TEXT,
    picked INTEGER NOT NULL DEFAULT 0,
    updated REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS jobs_open ON jobs (state);
CREATE TABLE IF NOT EXISTS transitions (
    n INTEGER PRIMARY KEY AUTOINCREMENT,
    job TEXT NOT NULL REFERENCES jobs (id),
    event TEXT NOT NULL,
    state TEXT NOT NULL,
    robot TEXT,
    picked INTEGER NOT NULL,
    stamp REAL NOT NULL,
    reason TEXT
);
CREATE TABLE IF NOT EXISTS outbox (
    id INTEGER PRIMARY KEY CHECK (id = 0),
    announced INTEGER NOT NULL
);
"""


class DuplicateJob(ValueError):
    """A job id the store already holds."""


@dataclass(frozen=True)
class StoredJob:
    """A job as the store holds it."""

    task: Task
    seq: int
    state: str
    robot: str | None
    picked: bool


@dataclass(frozen=True)
class Transition:
    """One change of a job's state."""

    event: str
    state: str
    robot: str | None
    picked: bool
    stamp: float
    reason: str | None


class StoreInUse(OSError):
    """Another process holds the job store's lock (another planner keeps its jobs there)."""


class JobStore:
    """Accepted jobs and their state changes in the SQLite file ``path`` (created, with its
    folders, if missing). Not closing it is safe: every change is committed when its call returns.

    With ``lock`` the store is this process's alone while it is open (an exclusive ``flock`` on
    ``<path>.lock``, which the system drops when the process ends, also by kill -9): a second
    planner on the same file gets :class:`StoreInUse`, never the first one's jobs."""

    def __init__(self, path: str | Path, lock: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = _take_lock(self.path) if lock else None
        self._db = sqlite3.connect(str(self.path), isolation_level=None, check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.execute("PRAGMA foreign_keys=ON")
        self._db.executescript(_SCHEMA)
        if self._db.execute("SELECT 1 FROM outbox").fetchone() is None:  # new, or from before the outbox:
            self._db.execute("INSERT OR IGNORE INTO outbox (id, announced) "   # what is there went out
                             "SELECT 0, COALESCE(MAX(n), 0) FROM transitions")

    def close(self) -> None:
        self._db.close()
        if self._lock is not None:
            self._lock.close()  # (the lock goes with it)
            self._lock = None

    def __enter__(self) -> JobStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writes: one transaction each ----------------------------------------------------------
    def add(self, task: Task, seq: int, stamp: float) -> int:
        """Record a newly accepted job (state queued): the number of its transition (see
        :meth:`mark_announced`). DuplicateJob if its id is known."""
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            db.execute("INSERT INTO jobs (id, task, seq, state, robot, picked, updated) "
                       "VALUES (?, ?, ?, 'queued', NULL, 0, ?)", (task.id, task.to_json(), seq, stamp))
            cur = db.execute("INSERT INTO transitions (job, event, state, robot, picked, stamp, reason) "
                             "VALUES (?, 'accepted', 'queued', NULL, 0, ?, NULL)", (task.id, stamp))
        except sqlite3.IntegrityError:
            db.execute("ROLLBACK")
            raise DuplicateJob(f"task.id: duplicate task id {task.id!r}") from None
        except BaseException:
            db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")
        return int(cur.lastrowid or 0)

    def update(self, job_id: str, event: str, state: str, robot: str | None, picked: bool, stamp: float,
               reason: str | None = None) -> int:
        """Record a change of the job ``job_id``: its new state, robot and picked flag. The number of
        the transition (see :meth:`mark_announced`)."""
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            cur = db.execute("UPDATE jobs SET state = ?, robot = ?, picked = ?, updated = ? WHERE id = ?",
                             (state, robot, int(picked), stamp, job_id))
            if cur.rowcount != 1:
                raise KeyError(f"job {job_id!r} is not in the store")
            cur = db.execute("INSERT INTO transitions (job, event, state, robot, picked, stamp, reason) "
                             "VALUES (?, ?, ?, ?, ?, ?, ?)", (job_id, event, state, robot, int(picked), stamp, reason))
        except BaseException:
            db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")
        return int(cur.lastrowid or 0)

    def mark_announced(self, upto: int) -> None:
        """The task events of every transition up to number ``upto`` went out (never moves back)."""
        self._db.execute("UPDATE outbox SET announced = ? WHERE id = 0 AND announced < ?", (upto, upto))

    def replace_task(self, task: Task, event: str, stamp: float, reason: str | None = None) -> None:
        """Record a changed task of a known job (the operator changed its priority), with the change."""
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            cur = db.execute("UPDATE jobs SET task = ?, updated = ? WHERE id = ?", (task.to_json(), stamp, task.id))
            if cur.rowcount != 1:
                raise KeyError(f"job {task.id!r} is not in the store")
            db.execute("INSERT INTO transitions (job, event, state, robot, picked, stamp, reason) "
                       "SELECT id, ?, state, robot, picked, ?, ? FROM jobs WHERE id = ?",
                       (event, stamp, reason, task.id))
        except BaseException:
            db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")

    # -- reads ---------------------------------------------------------------------------------
    def get(self, job_id: str) -> StoredJob | None:
        row = self._db.execute("SELECT task, seq, state, robot, picked FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else _job(row)

    def open_jobs(self) -> list[StoredJob]:
        """The jobs not done or failed, in submission order."""
        rows = self._db.execute("SELECT task, seq, state, robot, picked FROM jobs "
                                "WHERE state NOT IN ('done', 'failed', 'cancelled') ORDER BY seq").fetchall()
        return [_job(row) for row in rows]

    def next_seq(self) -> int:
        """One more than the largest submission order stored (0 for an empty store)."""
        row = self._db.execute("SELECT COALESCE(MAX(seq) + 1, 0) FROM jobs").fetchone()
        return int(row[0])

    def reason(self, job_id: str) -> str | None:
        """The reason of the job's last change that gave one (why it failed or was cancelled)."""
        row = self._db.execute("SELECT reason FROM transitions WHERE job = ? AND reason IS NOT NULL "
                               "ORDER BY n DESC LIMIT 1", (job_id,)).fetchone()
        return None if row is None else str(row[0])

    def history(self, job_id: str) -> list[Transition]:
        rows = self._db.execute("SELECT event, state, robot, picked, stamp, reason FROM transitions "
                                "WHERE job = ? ORDER BY n", (job_id,)).fetchall()
        return [Transition(e, s, r, bool(p), float(t), why) for e, s, r, p, t, why in rows]

    def announced_upto(self) -> int:
        """The number of the last transition marked announced (:meth:`mark_announced`)."""
        return int(self._db.execute("SELECT announced FROM outbox WHERE id = 0").fetchone()[0])

    def unannounced(self) -> list[tuple[str, Transition]]:
        """The transitions committed after the last one marked announced, in order, with their job's id."""
        rows = self._db.execute("SELECT job, event, state, robot, picked, stamp, reason FROM transitions "
                                "WHERE n > (SELECT announced FROM outbox WHERE id = 0) ORDER BY n").fetchall()
        return [(job, Transition(e, s, r, bool(p), float(t), why)) for job, e, s, r, p, t, why in rows]

    def counts(self) -> dict[str, int]:
        """How many jobs are in each state."""
        return {state: int(n) for state, n in self._db.execute("SELECT state, COUNT(*) FROM jobs GROUP BY state")}


def _take_lock(path: Path) -> IO[str]:
    """The open lock file of the store at ``path``, locked for this process (StoreInUse if another holds it)."""
    lock = open(path.with_name(path.name + ".lock"), "a+")
    try:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        lock.seek(0)
        holder = lock.read(40).strip()
        lock.close()
        raise StoreInUse(f"{str(path)!r} is in use by another planner (process {holder or '?'})") from None
    lock.seek(0)
    lock.truncate()
    lock.write(str(os.getpid()))
    lock.flush()
    return lock


def _job(row: tuple[str, int, str, str | None, int]) -> StoredJob:
    text, seq, state, robot, picked = row
    return StoredJob(cast(Task, Task.from_json(text)), int(seq), state, robot, bool(picked))


__all__ = ["CLOSED", "DEFAULT_FILE", "MEMORY", "RESENT", "DuplicateJob", "JobStore", "StoreInUse", "StoredJob",
           "Transition",
           "current_event", "default_path", "emptied", "open_store"]
