"""Parameter sweeps: every (object, settings) combination run once, each result stored as it finishes.

A sweep is a list of objects (built-in names, mesh files, globs, ``pybullet_data:`` globs) times a
grid of settings (:data:`SWEEP_KEYS`, the options of ``explore3d run``).  Every combination is one
:class:`RunTask`, identified by its :attr:`RunTask.key`: a hash of

* the object as given (built-in name, absolute file path, or ``pybullet_data:`` + the path in
  pybullet_data's folder) and its mesh hash (sha256 of the file's bytes; of the vertex and face
  arrays for a built-in);
* the settings' hash (sha256 of their canonical JSON: sorted keys, values as parsed, defaults
  left out, ``size`` included, ``seed`` apart);
* the seed (of the error measure's surface samples);
* the package version.

Rows go into an SQLite database ``sweep.db`` in the output folder (WAL, one commit per row, the
only writer is the sweep's own process), after the run's files (``runs/<key>/estimate.stl``,
``points.ply``, ``report.json``; planar runs also ``estimate_polygon.json``) and the true mesh
(``truths/<hash>.stl``, once per object and size) are written atomically, so a stored row always has its files.  A
sweep started again with the same command runs only the combinations without a row (and those
stored as ``lost``, below).  A run that fails (an exception, or a worker that crashes: PyBullet can
kill the process by SIGSEGV) is stored with status ``failed`` and a one-line reason; the sweep
goes on.  A run lost to the machinery rather than to itself (a worker that exits without a
result, or is killed from outside: SIGKILL, SIGTERM, SIGINT, SIGHUP; a Ray node that died) is
stored with status ``lost``: a plain rerun runs it again.

One sweep at a time per folder: :func:`run_sweep` holds an exclusive ``flock`` on
``sweep.lock`` in the folder (holder's pid inside) while it runs; the kernel releases it when the
holder dies (SIGKILL too).  A second sweep on the folder raises :class:`SweepBusyError` before
doing anything.  The local backend's workers die with the sweep (Linux: ``PR_SET_PDEATHSIG``,
elsewhere a thread that watches the parent's pid).

A ``sweep.db`` that is not a sweep's database (not SQLite, another schema, damaged) is refused
with :class:`SweepDatabaseError` and left as it is; readers (:func:`read_rows`) open it
read-only.

Backends run the same function (:func:`execute`) on the same tasks, so the stored rows do not
depend on the backend or the number of workers (only the timing columns, :data:`TIMING_COLUMNS`,
do):

* ``local`` (default): one fresh process (``spawn``) per run, at most ``workers`` at once; a
  crash ends that process only;
* ``ray``: Ray tasks on a new local Ray started on demand (``ray.init(address="local",
  num_cpus=workers x jobs_per_run)``, its workers at normal priority, nice 0: at Ray's default
  nice 15 a small run beside a two-worker sweep on the 2 cores took 101 s instead of 5 s) or an
  existing cluster (``address``, or the ``RAY_ADDRESS`` environment variable); each mesh is
  shipped once (``ray.put``); every PyBullet client is created inside the worker by the run
  itself.

Each run gets ``jobs_per_run`` processes for its wraps (``ExploreConfig.jobs``; results do not
depend on it).

Test hook: the environment variable ``EXPLORE3D_SWEEP_FAULT`` = ``"segfault:OBJECT"``,
``"raise:OBJECT"``, ``"exit:OBJECT"`` or ``"hang:OBJECT"`` (several separated by ``;``) makes the
runs of that object (as stored) die by SIGSEGV, raise, exit with code 0 without a result, or
sleep for an hour, in the worker.
"""
from __future__ import annotations

import contextlib
import glob
import hashlib
import itertools
import json
import math
import multiprocessing as mp
import os
import pickle
import signal
import sqlite3
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from multiprocessing.connection import wait
from pathlib import Path

import numpy as np
import trimesh
from tqdm import tqdm

from explore3d import __version__
from explore3d.app.export import write_mesh
from explore3d.app.grasp import GraspConfig, grasp_run
from explore3d.app.report import OutputConfig, run_and_report
from explore3d.app.settings import _BOOL_OPTIONS, RUN_DEFAULTS, RUN_OPTIONS, SWEEP_KEYS, UsageError, explore_config
from explore3d.arm.urdf import load_arm
from explore3d.core.interrupt import import_optional
from explore3d.core.io import atomic_write_bytes, json_text
from explore3d.core.lifeline import die_with_parent
from explore3d.core.quiet import STDERR, quiet_c_output
from explore3d.core.validate import read_toml
from explore3d.world.objects import BUILTIN_OBJECTS, PYBULLET_DATA_PREFIX, _resolve_path, load_object

__all__ = ["SWEEP_KEYS", "TIMING_COLUMNS", "RunTask", "SweepBusyError", "SweepDatabaseError", "SweepStore",
           "SweepSummary", "execute", "parse_grid", "read_grid_file", "read_rows", "resolve_objects", "run_sweep",
           "settings_grid", "sweep_tasks"]

#: Name of the database in a sweep's output folder.
DB_NAME = "sweep.db"

#: Name of the lock file in a sweep's output folder (see :func:`sweep_lock`).
LOCK_NAME = "sweep.lock"

#: Status of a run lost to the machinery (its worker exited without a result or was killed from
#: outside): stored so the report shows it, run again by a plain rerun.
LOST = "lost"

#: Signals that end a worker from outside (the user, a supervisor, the OOM killer): the run is
#: ``lost``, not ``failed``.  Any other signal (SIGSEGV, SIGABRT, SIGBUS, SIGFPE, ...) is the run's
#: own crash.
_EXTERNAL_SIGNALS = ("SIGKILL", "SIGTERM", "SIGINT", "SIGHUP")

#: Columns of a stored row that are wall-clock times (everything else is the same whichever
#: backend and however many workers ran it).
TIMING_COLUMNS = ("time_s", "timings")

#: Report entries that are wall-clock times: kept out of a row's ``report`` (in ``timings``).
_REPORT_TIMING_KEYS = ("timings", "wall_s")

#: Settings left out of the canonical settings when they have these values (what ``run`` does
#: without them), so ``--grid a=0.05`` and no ``a`` at all are the same combination.
_DEFAULTS = {"arm": "default", "method": "exponential", "mode": "3d", "encircle": "straight", "scene": "ideal",
             "grasp": 0}

_BOOL_WORDS = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}

SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    key TEXT PRIMARY KEY,
    object TEXT NOT NULL,
    mesh_sha256 TEXT NOT NULL,
    settings_sha256 TEXT NOT NULL,
    seed INTEGER NOT NULL,
    version TEXT NOT NULL,
    settings TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT,
    percent_error REAL,
    iou REAL,
    chamfer_m REAL,
    hausdorff_m REAL,
    n_wraps INTEGER,
    n_points INTEGER,
    n_contacts INTEGER,
    report TEXT,
    run_dir TEXT,
    truth TEXT,
    time_s REAL,
    timings TEXT
)
"""
_COLUMNS = ("key", "object", "mesh_sha256", "settings_sha256", "seed", "version", "settings", "status", "reason",
            "percent_error", "iou", "chamfer_m", "hausdorff_m", "n_wraps", "n_points", "n_contacts", "report",
            "run_dir", "truth", "time_s", "timings")


# --- settings -------------------------------------------------------------------------------------

def _checker(key: str):
    if key in _BOOL_OPTIONS:
        return "bool"
    return RUN_OPTIONS[key]


def parse_setting(key: str, value, *, from_text: bool):
    """One grid value of ``key`` as the run takes it (numbers checked as ``explore3d run`` checks
    them; ``arm`` files made absolute).  ``from_text``: ``value`` is a command-line string.
    Raises ValueError (one line) for an unknown key or a bad value."""
    key = str(key).replace("-", "_")
    if key not in SWEEP_KEYS:
        raise ValueError(f"unknown sweep setting {key!r}; valid keys: {', '.join(SWEEP_KEYS)}")
    check = _checker(key)
    try:
        if check == "bool":
            if isinstance(value, bool):
                return value
            word = str(value).strip().lower()
            if word not in _BOOL_WORDS:
                raise ValueError(f"{key} must be true or false; got {value!r}")
            return _BOOL_WORDS[word]
        if check is str:
            if not isinstance(value, str) or not value.strip():
                raise ValueError(f"{key} must be a non-empty string; got {value!r}")
            v = value.strip()
            if key == "arm" and Path(v).is_file():
                v = str(Path(v).resolve())
            return v
        if from_text:
            value = str(value).strip()
        v = check(value)
        return float(v) if isinstance(v, float) else v
    except UsageError as exc:
        raise ValueError(f"sweep setting {key}: {exc}") from None


def parse_grid(items) -> dict:
    """``["a=0.02,0.05", "arm=default,paper"]`` -> ``{"a": [0.02, 0.05], "arm": ["default", "paper"]}``,
    values checked (:func:`parse_setting`); a key given twice: ValueError."""
    grid: dict = {}
    for item in items or ():
        if not isinstance(item, str) or "=" not in item:
            raise ValueError(f"--grid takes KEY=V1,V2,...; got {item!r} (e.g. --grid a=0.02,0.05)")
        k, _, vals = item.partition("=")
        key = k.strip().replace("-", "_")
        values = [v for v in vals.split(",") if v.strip()]
        if not values:
            raise ValueError(f"--grid {k.strip()} has no values; give KEY=V1,V2,...")
        if key in grid:
            raise ValueError(f"--grid {key} is given twice; list all its values in one --grid {key}=V1,V2,...")
        grid[key] = [parse_setting(key, v, from_text=True) for v in values]
    return grid


def read_grid_file(path) -> dict:
    """A grid from a TOML file: top-level ``KEY = value`` or ``KEY = [v1, v2, ...]`` (keys of
    :data:`SWEEP_KEYS`), checked as :func:`parse_grid` checks flags."""
    path = Path(path)
    data = read_toml(path, "grid file", "--grid-file")
    grid = {}
    for k, v in data.items():
        key = k.replace("-", "_")
        values = v if isinstance(v, list) else [v]
        if not values or any(isinstance(x, (dict, list)) for x in values):
            raise ValueError(f"{k} in grid file {path} must be a value or a non-empty list of values; got {v!r}")
        grid[key] = [parse_setting(key, x, from_text=False) for x in values]
    return grid


def canonical_settings(settings: dict) -> dict:
    """``settings`` without ``seed`` and without the defaults of :data:`_DEFAULTS`, keys sorted."""
    return {k: settings[k] for k in sorted(settings)
            if k != "seed" and not (k in _DEFAULTS and settings[k] == _DEFAULTS[k])}


def _canonical_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def settings_grid(grid: dict) -> list[dict]:
    """Every combination of ``grid`` (key -> list of values), in the grid's key order, the last
    key varying fastest; one empty combination for an empty grid.  Duplicates are dropped."""
    keys = list(grid)
    out, seen = [], set()
    for combo in itertools.product(*(grid[k] for k in keys)):
        s = dict(zip(keys, combo))
        h = _canonical_json([canonical_settings(s), s.get("seed", 0)])
        if h not in seen:
            seen.add(h)
            out.append(s)
    return out


# --- objects --------------------------------------------------------------------------------------

def _is_glob(text: str) -> bool:
    return any(c in text for c in "*?[")


def resolve_objects(specs) -> list[str]:
    """Object specs -> object names as stored: built-in names as they are, files as absolute
    paths, ``pybullet_data:PATTERN`` as ``pybullet_data:`` + each matching path in pybullet_data's
    folder; globs expanded (sorted).  Order kept, duplicates dropped.  Raises ValueError (one line)
    for a name that is neither, or a glob that matches nothing."""
    if isinstance(specs, str):
        specs = [specs]
    out: list[str] = []
    for spec in specs:
        if not isinstance(spec, (str, os.PathLike)):
            raise ValueError(f"objects must be names, paths or globs; got {type(spec).__name__}")
        spec = str(spec)
        if spec in BUILTIN_OBJECTS:
            found = [spec]
        elif spec.startswith(PYBULLET_DATA_PREFIX):
            import pybullet_data  # start-up: pybullet's data package, only for pybullet_data: names

            root = Path(pybullet_data.getDataPath())
            pattern = spec[len(PYBULLET_DATA_PREFIX):]
            files = sorted(p for p in root.glob(pattern) if p.is_file()) if pattern else []
            if not files:
                raise ValueError(f"no file in pybullet_data matches {pattern!r} (looked in {root}); "
                                 "pass e.g. pybullet_data:duck_vhacd.obj or pybullet_data:toys/*.obj")
            found = [PYBULLET_DATA_PREFIX + p.relative_to(root).as_posix() for p in files]
        elif _is_glob(spec):
            files = sorted(p for p in glob.glob(spec, recursive=True) if Path(p).is_file())
            if not files:
                raise ValueError(f"no file matches {spec!r}; check the pattern (quote it so the shell leaves it)")
            found = [str(Path(p).resolve()) for p in files]
        else:
            p = Path(spec)
            if not p.is_file():
                if not p.suffix and "/" not in spec and os.sep not in spec:
                    raise ValueError(f"unknown object {spec!r}; use a built-in name ({', '.join(BUILTIN_OBJECTS)}), "
                                     "a mesh file, a glob or pybullet_data:PATTERN")
                raise ValueError(f"mesh file not found: {spec}; check the path")
            found = [str(p.resolve())]
        for name in found:
            if name not in out:
                out.append(name)
    if not out:
        raise ValueError("a sweep needs at least one object: pass built-in names, mesh files or globs")
    return out


def mesh_sha256(name: str) -> str:
    """sha256 of an object: of the file's bytes, or (built-in) of its float64 vertices and int64
    faces (C order)."""
    if name in BUILTIN_OBJECTS:
        m = BUILTIN_OBJECTS[name].builder()
        h = hashlib.sha256(np.ascontiguousarray(m.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(m.faces, dtype="<i8").tobytes())
        return h.hexdigest()
    return hashlib.sha256(_resolve_path(name).read_bytes()).hexdigest()


# --- tasks ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RunTask:
    """One (object, settings) combination of a sweep.

    Attributes:
        object: the object as stored (:func:`resolve_objects`).
        mesh_sha256: :func:`mesh_sha256` of it.
        settings: the settings (:data:`SWEEP_KEYS` -> value, ``size`` in metres), as swept.
        seed: seed of the error measure's surface samples.
        version: the explore3d version.
        jobs: processes for the run's wraps (``ExploreConfig.jobs``); not part of the key.
    """

    object: str
    mesh_sha256: str
    settings: dict = field(hash=False)
    seed: int = 0
    version: str = ""
    jobs: int = 1

    @property
    def settings_json(self) -> str:
        return _canonical_json(canonical_settings(self.settings))

    @property
    def settings_sha256(self) -> str:
        return _sha256_text(self.settings_json)

    @property
    def key(self) -> str:
        """20 hex digits of sha256 over (object, mesh hash, settings hash, seed, version)."""
        return _sha256_text(_canonical_json([self.object, self.mesh_sha256, self.settings_sha256, self.seed,
                                             self.version]))[:20]

    @property
    def size(self) -> float | None:
        return self.settings.get("size")


def sweep_tasks(objects, grid: dict | None = None, size: float | None = None, jobs_per_run: int = 1) -> list[RunTask]:
    """The tasks of a sweep: :func:`resolve_objects` x :func:`settings_grid` (objects outer).
    ``size`` (metres, the longest side, as ``explore3d run --size``) applies where the grid sets
    none."""
    grid = dict(grid or {})
    for k in grid:
        if k not in SWEEP_KEYS:
            raise ValueError(f"unknown sweep setting {k!r}; valid keys: {', '.join(SWEEP_KEYS)}")
    if size is not None:
        size = parse_setting("size", size, from_text=False)
        grid.setdefault("size", [size])
    if "arm" in grid:
        for arm in grid["arm"]:
            load_arm(arm)  # a one-line ValueError for an unknown arm, before any run
    names = resolve_objects(objects)
    combos = settings_grid(grid)
    hashes = {n: mesh_sha256(n) for n in names}
    return [RunTask(object=n, mesh_sha256=hashes[n], settings=s, seed=int(s.get("seed", 0)), version=__version__,
                    jobs=jobs_per_run) for n in names for s in combos]


def one_line(exc: BaseException, limit: int = 400) -> str:
    """``Type: message`` on one line, at most ``limit`` characters."""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fault_hook(task: RunTask) -> None:
    """The test hook of the module docstring (entries separated by ';')."""
    for spec in os.environ.get("EXPLORE3D_SWEEP_FAULT", "").split(";"):
        what, _, obj = spec.partition(":")
        if obj != task.object:
            continue
        if what == "segfault":
            os.kill(os.getpid(), signal.SIGSEGV)
        elif what == "raise":
            raise RuntimeError(f"injected failure (EXPLORE3D_SWEEP_FAULT={spec})")
        elif what == "exit":
            os._exit(0)
        elif what == "hang":
            time.sleep(3600.0)


def execute(task: RunTask, vertices, faces, arm=None) -> dict:
    """Run ``task`` on the mesh (``vertices`` (n, 3) float metres, ``faces`` (f, 3) int) in this
    process, as ``explore3d run`` would (no pictures, the estimate as STL).  ``arm``: the
    :class:`~explore3d.arm.spec.ArmSpec` of ``task.settings["arm"]`` (loaded here when None).

    Returns ``{"status": "ok", "report": dict, "files": {name: bytes}, "time_s": s}`` or
    ``{"status": "failed", "reason": one line, "time_s": s}``; never raises an Exception."""
    t0 = time.perf_counter()
    try:
        _fault_hook(task)
        s = task.settings
        opts = {**{k: RUN_DEFAULTS[k] for k in ("arm", "mode", "a", "method")}, **s, "jobs": task.jobs}
        try:
            config = explore_config(opts)
        except Exception as exc:  # cli.UsageError
            raise ValueError(str(exc)) from None
        spec = arm if arm is not None else load_arm(opts["arm"])
        mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64), process=False)
        with quiet_c_output(), tempfile.TemporaryDirectory(prefix="explore3d-sweep-") as d:
            _, report = run_and_report(mesh, spec, config, d, output=OutputConfig(fmt="stl", pictures=False),
                                       a=float(opts["a"]), method=opts["method"], seed=task.seed,
                                       object_name=task.object, source={"size": s.get("size")})
            if s.get("grasp"):  # evaluation after the run: grasps planned on it, executed on the truth
                if config.mode != "3d":
                    raise ValueError(f"grasp plans grasps on a 3D estimate; this run's mode is {config.mode!r}")
                grasp_run(d, GraspConfig(n=s["grasp"]), pictures=False, truth=mesh)
                report = json.loads((Path(d) / "report.json").read_text(encoding="utf-8"))
            files = {n: (Path(d) / n).read_bytes() for n in ("estimate.stl", "points.ply", "estimate_polygon.json")
                     if (Path(d) / n).is_file()}
        return {"status": "ok", "report": report, "files": files, "time_s": time.perf_counter() - t0}
    except Exception as exc:  # a failed run is a result, not the end of the sweep
        return {"status": "failed", "reason": one_line(exc), "time_s": time.perf_counter() - t0}


# --- storage --------------------------------------------------------------------------------------

class SweepDatabaseError(ValueError):
    """A ``sweep.db`` that cannot be used: not SQLite, another schema, damaged, or not readable
    or writable here.  The message is one line naming the file, what is wrong and the fix."""


class SweepBusyError(ValueError):
    """Another sweep holds the folder's lock (:func:`sweep_lock`); the message names the folder,
    the holder's pid and the fix."""


def _is_unopenable(exc: sqlite3.Error) -> bool:
    """An error of opening (permissions, a missing or read-only folder), not of the file's bytes."""
    text = str(exc).lower()
    return any(w in text for w in ("unable to open", "readonly", "read-only", "permission"))


def _check_database(db: sqlite3.Connection, path: Path, fix: str, deep: bool = True) -> bool:
    """Raise :class:`SweepDatabaseError` unless ``db`` is a sound sweep database; False when it
    has no table at all (a new, empty file), True for a sweep's database.  Reads only: the schema,
    and (``deep``) the whole file, by ``PRAGMA quick_check``.  An error of opening (permissions)
    is raised as it is."""
    try:
        tables = sorted(r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'"))
        if not tables:
            return False
        problem = None
        if "runs" not in tables:
            problem = f"it has no runs table; its tables: {', '.join(tables)}"
        else:
            columns = {r[1] for r in db.execute("PRAGMA table_info(runs)")}
            missing = [c for c in _COLUMNS if c not in columns]
            if missing:
                problem = f"its runs table lacks the columns {', '.join(missing)}"
            elif deep:
                found = [r[0] for r in db.execute("PRAGMA quick_check(1)")]
                if found != ["ok"]:
                    problem = f"damaged: {found[0] if found else 'quick_check found nothing'}"
    except sqlite3.DatabaseError as exc:
        if isinstance(exc, sqlite3.OperationalError) and _is_unopenable(exc):
            raise
        problem = str(exc) or type(exc).__name__
    if problem is not None:
        raise SweepDatabaseError(f"{path} is not an explore3d sweep database ({' '.join(problem.split())}); {fix}")
    return True


class SweepStore:
    """The rows of a sweep in ``folder/sweep.db`` (SQLite, WAL, one commit per row).

    Only the sweep's own process writes (:func:`run_sweep` holds the folder's lock); :meth:`put`
    replaces a row with the same key.  An existing ``sweep.db`` is checked before anything is
    written to it (:class:`SweepDatabaseError`, the file left as it is); so is a folder or file
    that cannot be written."""

    def __init__(self, folder, deep_check: bool = True):
        """``deep_check``: read the whole existing file to find damage (PRAGMA quick_check),
        not only its schema (:func:`run_sweep` has done it before taking the lock)."""
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / DB_NAME
        fix = "move it away or choose another --out"
        try:
            self.db = sqlite3.connect(self.path, timeout=30.0)
        except sqlite3.Error as exc:
            raise SweepDatabaseError(f"cannot open {self.path} ({exc}); choose a writable --out") from None
        try:
            _check_database(self.db, self.path, fix, deep_check)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=FULL")
            self.db.execute(SCHEMA)
            self.db.commit()
        except SweepDatabaseError:
            self.db.close()
            raise
        except sqlite3.Error as exc:
            self.db.close()
            if _is_unopenable(exc):
                raise SweepDatabaseError(f"cannot write {self.path} ({exc}); choose a writable --out") from None
            raise SweepDatabaseError(f"{self.path} is not an explore3d sweep database ({exc}); {fix}") from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def statuses(self) -> dict:
        """key -> status of every stored row."""
        return dict(self.db.execute("SELECT key, status FROM runs"))

    def outcomes(self) -> dict:
        """key -> (status, reason, object) of every stored row."""
        return {k: (st, r, o) for k, st, r, o in self.db.execute("SELECT key, status, reason, object FROM runs")}

    def put(self, row: dict) -> None:
        missing = set(_COLUMNS) - set(row)
        if missing:
            raise ValueError(f"a sweep row needs {sorted(missing)}")
        try:
            self.db.execute(f"INSERT OR REPLACE INTO runs ({', '.join(_COLUMNS)}) "
                            f"VALUES ({', '.join('?' * len(_COLUMNS))})", [row[c] for c in _COLUMNS])
            self.db.commit()
        except sqlite3.Error as exc:
            raise SweepDatabaseError(f"cannot store a row in {self.path} ({exc}); free the disk or fix the folder's "
                                     "permissions, then run the same command again (stored rows are kept)") from None

    def rows(self) -> list[dict]:
        """Every row as a dict of :data:`_COLUMNS`, ordered by object, then settings, then seed."""
        return _select_rows(self.db)


def _select_rows(db) -> list[dict]:
    cur = db.execute(f"SELECT {', '.join(_COLUMNS)} FROM runs ORDER BY object, settings, seed, version")
    return [dict(zip(_COLUMNS, r)) for r in cur]


def _connect_read_only(path: Path, fix: str, deep: bool = True) -> tuple[sqlite3.Connection, bool]:
    """``path`` opened read-only, never for writing, and checked (:func:`_check_database`:
    whether it has tables).  Without a ``-wal`` file beside it (no sweep is writing it; a sweep's
    last close folds the log into the file) the file holds every row and is opened ``immutable``:
    nothing is created beside it, so this works in a read-only folder.  With one, ``mode=ro``:
    SQLite reads the log through its ``-shm`` index, which it may need to create.  Raises
    :class:`SweepDatabaseError`."""
    uri = path.resolve().as_uri()
    wal = path.with_name(path.name + "-wal")
    live = wal.is_file() and wal.stat().st_size > 0  # an empty log (left by a reader) holds no rows
    db = None
    try:
        db = sqlite3.connect(f"{uri}?mode=ro" if live else f"{uri}?mode=ro&immutable=1", uri=True, timeout=30.0)
        return db, _check_database(db, path, fix, deep)
    except sqlite3.Error as exc:
        if db is not None:
            db.close()
        if not _is_unopenable(exc):
            raise SweepDatabaseError(f"{path} is not an explore3d sweep database ({exc}); {fix}") from None
        if live:
            raise SweepDatabaseError(f"cannot read {path} read-only ({exc}): its write-ahead log {wal.name} holds rows "
                                     "that need its -shm index, which cannot be created here; run the command as a "
                                     "user who can write the folder, or wait for the sweep to finish") from None
        raise SweepDatabaseError(f"cannot read {path} ({exc}); check the file's permissions") from None
    except BaseException:
        if db is not None:
            db.close()
        raise


def read_rows(folder) -> list[dict]:
    """The rows of the sweep in ``folder``, read without writing anything (read-only open).
    Raises ValueError if it holds no sweep.db, :class:`SweepDatabaseError` if that is not a
    sweep's database (or an empty file: no sweep yet)."""
    folder = Path(folder)
    path = folder / DB_NAME
    if not path.is_file():
        raise ValueError(f"{folder} holds no {DB_NAME}; pass the --out folder of an 'explore3d sweep'")
    if not os.access(path, os.R_OK):
        raise SweepDatabaseError(f"cannot read {path} (permission denied); check the file's permissions")
    fix = "move it away, or pass the --out folder of an 'explore3d sweep'"
    db, has_tables = _connect_read_only(path, fix)
    try:
        if not has_tables:
            raise SweepDatabaseError(f"{path} is not an explore3d sweep database (it has no table); {fix}")
        try:
            return _select_rows(db)
        except sqlite3.DatabaseError as exc:
            raise SweepDatabaseError(f"{path} is not an explore3d sweep database ({exc}); {fix}") from None
    finally:
        db.close()


def _row(task: RunTask, outcome: dict, truth: str | None) -> dict:
    row = {"key": task.key, "object": task.object, "mesh_sha256": task.mesh_sha256,
           "settings_sha256": task.settings_sha256, "seed": task.seed, "version": task.version,
           "settings": task.settings_json, "status": outcome["status"], "reason": outcome.get("reason"),
           "percent_error": None, "iou": None, "chamfer_m": None, "hausdorff_m": None, "n_wraps": None,
           "n_points": None, "n_contacts": None, "report": None, "run_dir": None, "truth": truth,
           "time_s": float(outcome.get("time_s", math.nan)), "timings": None}
    if outcome["status"] == "ok":
        rep = json.loads(json_text(outcome["report"]))
        timing = {k: rep.pop(k) for k in _REPORT_TIMING_KEYS if k in rep}
        for k in ("percent_error", "iou", "chamfer_m", "hausdorff_m"):
            row[k] = float(rep[k])
        for k in ("n_wraps", "n_points", "n_contacts"):
            row[k] = int(rep[k])
        row["report"] = _canonical_json(rep)
        row["timings"] = _canonical_json(timing)
        row["run_dir"] = f"runs/{task.key}"
    return row


# --- backends -------------------------------------------------------------------------------------

def _child_main(task, vertices, faces, arm, result_path, parent_pid) -> None:
    """A local worker process: run one task, leave its outcome (pickle) at ``result_path``; it dies
    with the sweep's process ``parent_pid`` (:func:`explore3d.core.lifeline.die_with_parent`)."""

    die_with_parent(parent_pid)
    outcome = execute(task, vertices, faces, arm)
    atomic_write_bytes(result_path, pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL))


def _exit_outcome(code) -> dict:
    """The outcome of a worker that ended with exit code ``code`` and left no result: ``failed``
    when it crashed by itself (a signal such as SIGSEGV), :data:`LOST` when it was killed from
    outside (:data:`_EXTERNAL_SIGNALS`) or exited without a result."""
    if code is not None and code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        if name in _EXTERNAL_SIGNALS:
            return {"status": LOST, "reason": f"worker killed by {name} from outside the run (a plain rerun runs "
                                              "it again)", "time_s": math.nan}
        return {"status": "failed", "reason": f"worker crashed: killed by {name} (PyBullet or a native library "
                                              "failed in the run)", "time_s": math.nan}
    return {"status": LOST, "reason": f"worker exited with code {code} without a result (a plain rerun runs it "
                                      "again)", "time_s": math.nan}


def _local_backend(jobs, workers: int, work_dir: Path, on_start):
    """Yield (task, outcome) as runs finish: each task of ``jobs`` ((task, mesh, arm)) in a fresh
    ``spawn`` process, at most ``workers`` at once."""

    ctx = mp.get_context("spawn")
    pending = deque(jobs)
    running: dict = {}  # sentinel -> (process, task, result path)
    work_dir.mkdir(parents=True, exist_ok=True)
    try:
        while pending or running:
            while pending and len(running) < workers:
                task, (V, F), arm = pending.popleft()
                path = work_dir / f"{task.key}.pkl"
                path.unlink(missing_ok=True)
                p = ctx.Process(target=_child_main, args=(task, V, F, arm, path, os.getpid()),
                                name=f"explore3d-sweep-{task.key}")
                p.start()
                running[p.sentinel] = (p, task, path)
                on_start(task)
            for s in wait(list(running)):
                p, task, path = running.pop(s)
                p.join()
                if p.exitcode == 0 and path.is_file():
                    outcome = pickle.loads(path.read_bytes())
                    path.unlink()
                else:
                    outcome = _exit_outcome(p.exitcode)
                yield task, outcome
    finally:
        for p, _, path in running.values():  # interrupted: end the processes this sweep started
            p.terminate()
            p.join()
            path.unlink(missing_ok=True)


def _ray_execute(task, mesh, arm):
    """The Ray task: ``mesh`` is the (vertices, faces) pair put once in the object store."""
    return execute(task, mesh[0], mesh[1], arm)


def _ray_backend(jobs, workers: int, jobs_per_run: int, address, on_start):
    """Yield (task, outcome) as Ray tasks finish (see the module docstring)."""
    try:
        ray = import_optional("ray")  # an interrupted import raises KeyboardInterrupt, not "ray missing"
    except (ImportError, OSError) as exc:
        raise ValueError(f"the Ray backend needs ray ({exc}); pip install 'explore3d[ray]', or drop --ray "
                         "(and unset RAY_ADDRESS) for local processes") from None
    started = False
    if not ray.is_initialized():
        kw = dict(include_dashboard=False, log_to_driver=False, logging_level="ERROR", configure_logging=True)
        address = address or os.environ.get("RAY_ADDRESS") or None
        if address:
            ray.init(address=address, **kw)
        else:
            ray.init(address="local", num_cpus=workers * jobs_per_run, _system_config={"worker_niceness": 0}, **kw)
        started = True
    try:
        remote = ray.remote(num_cpus=jobs_per_run, max_retries=0)(_ray_execute)
        refs: dict = {}
        futures = {}
        for task, mesh, arm in jobs:
            mid = id(mesh)
            if mid not in refs:
                refs[mid] = ray.put(mesh)  # each mesh once
            futures[remote.remote(task, refs[mid], arm)] = task
            on_start(task)
        while futures:
            (ref,), _ = ray.wait(list(futures), num_returns=1)
            task = futures.pop(ref)
            try:
                outcome = ray.get(ref)
            except ray.exceptions.RayError as exc:  # the worker died (a crash in PyBullet) or Ray failed
                first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
                crashed = isinstance(exc, (ray.exceptions.WorkerCrashedError, ray.exceptions.RayTaskError))
                what = "worker crashed" if crashed else "lost to Ray (a plain rerun runs it again)"
                outcome = {"status": "failed" if crashed else LOST,
                           "reason": " ".join(f"{what}: {type(exc).__name__}: {first}".split())[:400],
                           "time_s": math.nan}
            yield task, outcome
    finally:
        if started:
            ray.shutdown()


# --- the sweep ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SweepSummary:
    """What :func:`run_sweep` did: ``total`` combinations, ``stored_before`` (skipped),
    ``ran``, ``ok``, ``failed`` and ``lost`` (of those run: ``ran = ok + failed + lost``), the
    ``folder``; ``ok_total``: combinations of the sweep stored as ok after it (those stored before
    included); ``first_failure``: ``"object: reason"`` of the first combination not ok (None when
    all are)."""

    total: int
    stored_before: int
    ran: int
    ok: int
    failed: int
    lost: int
    folder: str
    ok_total: int
    first_failure: str | None = None

    @property
    def not_ok_total(self) -> int:
        """Combinations of the sweep stored as failed or lost."""
        return self.total - self.ok_total


@contextlib.contextmanager
def sweep_lock(folder):
    """Hold the exclusive lock of the sweep folder ``folder`` (created): ``flock(LOCK_EX |
    LOCK_NB)`` on ``folder/sweep.lock``, which then holds this process's pid.  The kernel releases
    the lock when the holder ends, SIGKILL included.  Raises :class:`SweepBusyError` at once when
    another process holds it (without fcntl, i.e. not on a POSIX system: no lock)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl  # optional extra of the platform: POSIX only
    except ImportError:  # pragma: no cover - not POSIX
        yield None
        return
    path = folder / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            raise SweepBusyError(f"another sweep (pid {holder}) is running on {folder}; wait for it to end, or choose "
                                 "another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        try:
            yield path
        finally:
            os.ftruncate(fd, 0)
    finally:
        os.close(fd)  # releases the lock


#: Reason with which earlier versions stored a worker that exited without a result as failed:
#: such rows are lost runs, run again by a plain rerun.
_LEGACY_LOST_REASON = "worker exited with code "


def _to_run(outcome, retry_failed: bool) -> bool:
    """Whether a combination stored with ``outcome`` ((status, reason, object) or None) runs."""
    if outcome is None:
        return True
    status, reason = outcome[0], outcome[1] or ""
    if status == "ok":
        return False
    return retry_failed or status == LOST or reason.startswith(_LEGACY_LOST_REASON)


def _write_truth(folder: Path, task: RunTask, mesh) -> str:
    """The true mesh once per (object, size) under ``truths/``; its path relative to ``folder``."""
    name = f"truths/{_sha256_text(_canonical_json([task.mesh_sha256, task.size]))[:20]}.stl"
    if not (folder / name).is_file():
        write_mesh(mesh, folder / name, "stl")
    return name


def run_sweep(objects, out, grid: dict | None = None, *, size: float | None = None, workers: int = 1,
              jobs_per_run: int = 1, backend: str = "local", ray_address: str | None = None,
              retry_failed: bool = False, progress: bool = True) -> SweepSummary:
    """Run every combination of ``objects`` x ``grid`` that ``out/sweep.db`` has no row for.

    Args:
        objects: names, files, globs or ``pybullet_data:`` globs (:func:`resolve_objects`).
        out: output folder (created): ``sweep.db``, ``runs/<key>/`` (estimate.stl, points.ply,
            report.json), ``truths/`` (the true meshes, STL).
        grid: setting -> list of values (:func:`parse_grid`, :func:`read_grid_file`).
        size: the objects' longest side, metres (where the grid sets no ``size``).
        workers: runs at once (local processes, or the local Ray's CPUs / ``jobs_per_run``).
        jobs_per_run: processes per run (its wraps).
        backend: "local" or "ray".  ray_address: an existing Ray cluster (default: ``RAY_ADDRESS``).
        retry_failed: run the combinations stored as failures again (those stored as ``lost``
            always run again).
        progress: a tqdm bar on stderr.

    Raises :class:`SweepBusyError` when another sweep runs on ``out`` (nothing done),
    :class:`SweepDatabaseError` when ``out/sweep.db`` is not a sweep's database (left as it is),
    OSError when ``out`` cannot be written.
    """
    if backend not in ("local", "ray"):
        raise ValueError(f"backend must be 'local' or 'ray'; got {backend!r}")
    for name, v in (("workers", workers), ("jobs_per_run", jobs_per_run)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
    folder = Path(out)
    tasks = sweep_tasks(objects, grid, size=size, jobs_per_run=jobs_per_run)
    path = folder / DB_NAME
    if path.is_file() and path.stat().st_size > 0 and os.access(path, os.R_OK):
        # not a sweep's database (not SQLite, another schema, damaged): refused before anything
        # (the lock file too) is written beside it
        _connect_read_only(path, "move it away or choose another --out")[0].close()
    with sweep_lock(folder), SweepStore(folder, deep_check=False) as store:
        done = store.outcomes()
        todo = [t for t in tasks if _to_run(done.get(t.key), retry_failed)]
        stored_before = len(tasks) - len(todo)
        bar = None
        if progress:
            bar = tqdm(total=len(tasks), initial=stored_before, desc="sweep", unit="run", file=STDERR,
                       dynamic_ncols=True)
        in_hand: list[str] = []

        def show():
            if bar is not None:
                bar.set_postfix_str(", ".join(Path(o).name for o in in_hand[-3:]) or "-", refresh=True)

        def on_start(task):
            in_hand.append(task.object)
            show()

        meshes: dict = {}  # (object, size) -> (vertices, faces), truth path
        arms: dict = {}
        jobs, failed_early = [], []
        for t in todo:
            mk = (t.object, t.size)
            if mk not in meshes:
                try:
                    m = load_object(t.object, size=t.size)
                    meshes[mk] = ((m.vertices.copy(), m.faces.copy()), _write_truth(folder, t, m))
                except ValueError as exc:  # an unreadable or open mesh: a failure of its runs, not the sweep
                    meshes[mk] = (None, one_line(exc))
            mesh, info = meshes[mk]
            if mesh is None:
                failed_early.append((t, {"status": "failed", "reason": info, "time_s": 0.0}))
                continue
            arm_name = t.settings.get("arm", "default")
            if arm_name not in arms:
                arms[arm_name] = load_arm(arm_name)
            jobs.append((t, mesh, arms[arm_name]))
        n_ok = n_failed = n_lost = 0

        def store_one(task, outcome):
            nonlocal n_ok, n_failed, n_lost
            truth = meshes[(task.object, task.size)][1] if outcome["status"] == "ok" else None
            if outcome["status"] == "ok":
                run_dir = folder / "runs" / task.key
                for name, data in outcome["files"].items():
                    atomic_write_bytes(run_dir / name, data)
                atomic_write_bytes(run_dir / "report.json", json_text(outcome["report"]).encode("utf-8"))
                n_ok += 1
            elif outcome["status"] == LOST:
                n_lost += 1
            else:
                n_failed += 1
            store.put(_row(task, outcome, truth))
            if task.object in in_hand:
                in_hand.remove(task.object)
            if bar is not None:
                bar.update(1)
                show()

        try:
            for task, outcome in failed_early:
                store_one(task, outcome)
            if jobs:
                it = (_local_backend(jobs, workers, folder / ".work", on_start) if backend == "local"
                      else _ray_backend(jobs, workers, jobs_per_run, ray_address, on_start))
                for task, outcome in it:
                    store_one(task, outcome)
        finally:
            if bar is not None:
                bar.close()
            if (folder / ".work").is_dir() and not any((folder / ".work").iterdir()):
                (folder / ".work").rmdir()
        after = store.outcomes()
    stored = [after.get(t.key) for t in tasks]
    first = next((f"{Path(o[2]).name}: {o[1]}" for o in stored if o is not None and o[0] != "ok"), None)
    return SweepSummary(total=len(tasks), stored_before=stored_before, ran=n_ok + n_failed + n_lost, ok=n_ok,
                        failed=n_failed, lost=n_lost, folder=str(folder),
                        ok_total=sum(o is not None and o[0] == "ok" for o in stored), first_failure=first)
