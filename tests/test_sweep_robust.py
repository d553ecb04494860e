"""``explore3d sweep`` and ``sweep-report`` interrupted, killed, run twice at once or fed garbage:
one line on stderr, exit 1 (2 for usage), nothing lost and nothing half-written.

The simulated runs use the small 16-link arm in planar mode with 3 directions (a few seconds a
run), as tests/test_sweep.py does; the failing objects are mesh files that are not meshes (they
fail before any simulation)."""
import os
import pwd
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import pytest
import trimesh

from explore3d.app.cli import main
from explore3d.app.sweep import DB_NAME, LOCK_NAME, LOST, SweepDatabaseError, SweepStore, _COLUMNS, _exit_outcome, read_rows, run_sweep

ROOT = Path(__file__).resolve().parents[1]


def _one_line(err, prefix="explore3d: error: "):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(prefix) and "Traceback" not in err, err
    return lines[0]


def _env(**extra):
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra}


def _cli(*argv, **kw):
    """``explore3d ARGV`` in a fresh process (stdout, stderr captured as text)."""
    return subprocess.run([sys.executable, "-m", "explore3d", *map(str, argv)], env=kw.pop("env", _env()),
                          capture_output=True, text=True, timeout=kw.pop("timeout", 120), **kw)


def _snapshot(folder: Path) -> dict:
    """Every file under ``folder``: relative path -> (bytes, mtime_ns)."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _alive(procs) -> list:
    """The processes of ``procs`` still running (a zombie has ended: only its exit status is left)."""
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


@pytest.fixture(scope="module")
def junk(tmp_path_factory):
    """Two mesh files that are not meshes (their runs fail before any simulation)."""
    d = tmp_path_factory.mktemp("junk")
    for name in ("junk1.stl", "junk2.stl"):
        (d / name).write_text("not a mesh\n")
    return [str(d / "junk1.stl"), str(d / "junk2.stl")]


@pytest.fixture(scope="module")
def setup(tmp_path_factory, junk):
    """The small arm, a box file, the planar grid (argv form), and the contact band measured once
    (the runs read it from the disk cache), the junk files."""
    from explore3d import ArmSpec, ExploreConfig, cached_band, write_arm_urdf

    d = tmp_path_factory.mktemp("robust")
    spec = ArmSpec(name="small16", n_links=16, link_length=0.02)
    arm = str(write_arm_urdf(spec, d / "small16.urdf"))
    trimesh.creation.box([0.07, 0.05, 0.06]).export(d / "box.stl")
    cfg = ExploreConfig(mode="planar")
    cached_band(spec, cfg.control, cfg.sim, cfg.sensors, True)
    grid = ["--grid", "mode=planar", "--grid", "directions=3", "--grid", f"arm={arm}", "--grid", "a=0.05"]
    return {"dir": d, "grid": grid, "box": str(d / "box.stl"), "junk": junk}




# --- 1. one sweep at a time per folder; lost runs run again ------------------------------------

def _kill_sweep_and_check_family(proc, family) -> None:
    """SIGKILL the sweep ``proc`` only (not its process group); every process of ``family`` must
    be gone within 5 s."""
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 5
    while _alive(family) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(family), [p.cmdline() for p in _alive(family)]


def _reap_group(proc) -> None:
    """Kill whatever of ``proc``'s process group is left (the test's own cleanup)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


def test_second_sweep_on_a_busy_folder_refuses_and_the_first_loses_nothing(setup, tmp_path):
    out = tmp_path / "busy"
    argv = [sys.executable, "-m", "explore3d", "sweep", "cube", *setup["grid"], "--out", str(out), "-q"]  # one run
    first = subprocess.Popen(argv, env=_env(), start_new_session=True, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and first.poll() is None and not any(
                "multiprocessing" in " ".join(c.cmdline()) for c in _alive(psutil.Process(first.pid).children())):
            time.sleep(0.1)
        assert first.poll() is None, "the first sweep ended before its runs started"
        t0 = time.monotonic()
        second = _cli(*argv[3:])
        took = time.monotonic() - t0
        assert first.poll() is None, "the first sweep ended before the second was refused: the test proves nothing"
        line = _one_line(second.stderr)
        assert second.returncode == 1 and second.stdout == ""
        assert str(out) in line and f"pid {first.pid}" in line and "another --out" in line, line
        assert took < 20  # refused at once: no run (a run takes seconds), only the start of Python
        rc = first.wait(timeout=120)
        assert rc == 0, first.stderr.read()
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()
    rows = read_rows(out)
    assert [r["status"] for r in rows] == ["ok"], [r["reason"] for r in rows]
    assert not (out / ".work").exists()
    assert (out / LOCK_NAME).read_text() == ""  # released: no holder's pid left behind
    # the lock is free again: the same command runs nothing, changes nothing
    assert main(["sweep", "cube", *setup["grid"], "--out", str(out), "-q"]) == 0
    assert read_rows(out) == rows


def test_lost_runs_run_again_and_failures_stay(tmp_path, monkeypatch):
    out = tmp_path / "lost"
    # a worker that exits with code 0 without a result (what two sweeps on one folder did to each other)
    monkeypatch.setenv("EXPLORE3D_SWEEP_FAULT", "exit:cube")
    s = run_sweep(["cube"], out, progress=False)
    assert (s.ran, s.ok, s.failed, s.lost) == (1, 0, 0, 1)
    (row,) = read_rows(out)
    assert row["status"] == LOST and "without a result" in row["reason"] and "\n" not in row["reason"]
    # a plain rerun runs it again; this time the run itself fails (an exception in the run)
    monkeypatch.setenv("EXPLORE3D_SWEEP_FAULT", "raise:cube")
    s = run_sweep(["cube"], out, progress=False)
    assert (s.stored_before, s.ran, s.failed, s.ok_total) == (0, 1, 1, 0)
    (row,) = read_rows(out)
    assert row["status"] == "failed" and row["reason"].startswith("RuntimeError: injected failure")
    # a genuine failure is a result: a plain rerun keeps it
    assert run_sweep(["cube"], out, progress=False).ran == 0
    # a row stored as failed by an earlier version for a worker without a result is a lost run
    db = sqlite3.connect(out / DB_NAME)
    db.execute("UPDATE runs SET reason = 'worker exited with code 0 without a result'")
    db.commit()
    db.close()
    assert run_sweep(["cube"], out, progress=False).ran == 1


def test_exit_outcomes():
    for code, status in ((-int(signal.SIGKILL), LOST), (-int(signal.SIGTERM), LOST), (0, LOST), (1, LOST),
                         (-int(signal.SIGSEGV), "failed"), (-int(signal.SIGABRT), "failed")):
        out = _exit_outcome(code)
        assert out["status"] == status and "\n" not in out["reason"], (code, out)


# --- 2. a sweep.db that is not a sweep's ---------------------------------------------------------

def _truncated(path: Path) -> None:
    """A sweep's database of 300 rows cut in half."""
    with SweepStore(path.parent) as store:
        for i in range(300):
            store.put({**{c: None for c in _COLUMNS}, "key": f"k{i:05d}", "object": "cube", "mesh_sha256": "h",
                       "settings_sha256": "s", "seed": 0, "version": "v", "settings": "{}", "status": "failed",
                       "reason": f"reason {i} " * 40})
    size = path.stat().st_size
    with open(path, "r+b") as f:
        f.truncate(size // 2)


def _foreign(path: Path) -> None:
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE people (name TEXT, age INTEGER)")
    db.execute("INSERT INTO people VALUES ('ada', 36)")
    db.commit()
    db.close()


def _foreign_runs(path: Path) -> None:
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE runs (key TEXT, speed REAL)")
    db.commit()
    db.close()


@pytest.mark.parametrize("kind, make, words", [
    ("text", lambda p: p.write_text("key,status\nabc,ok\n"), "file is not a database"),
    ("bytes", lambda p: p.write_bytes(bytes(range(256)) * 64), "file is not a database"),
    ("foreign", _foreign, "no runs table; its tables: people"),
    ("foreign-runs", _foreign_runs, "lacks the columns"),
    ("truncated", _truncated, "malformed"),
])
def test_not_a_sweep_database_is_refused_and_left_alone(junk, tmp_path, capsys, kind, make, words):
    folder = tmp_path / kind
    folder.mkdir()
    path = folder / DB_NAME
    make(path)
    before = _snapshot(folder)
    for argv in (["sweep", junk[0], "--out", str(folder), "-q"], ["sweep-report", str(folder)]):
        assert main(argv) == 1, argv
        cap = capsys.readouterr()
        line = _one_line(cap.err)
        assert f"{path} is not an explore3d sweep database" in line and words in line and "move it away" in line
        assert cap.out == ""
        assert _snapshot(folder) == before  # the file untouched, nothing written beside it
    with pytest.raises(SweepDatabaseError, match="not an explore3d sweep database"):
        read_rows(folder)


# --- 3. the report of a read-only sweep folder ---------------------------------------------------

@pytest.fixture
def shared_dir():
    """A folder another user can enter (pytest's tmp_path is private to its user)."""
    d = Path(tempfile.mkdtemp(prefix="explore3d-ro-"))
    d.chmod(0o755)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def _as_reader(folder: Path, writable: Path):
    """(command prefix, run kwargs, restore) to run a command that cannot write ``folder`` but can
    write ``writable``: as root, as the user nobody (root ignores permissions), by setpriv (or
    subprocess's ``user``); otherwise as this user with ``folder`` made read-only."""
    env = _env(HOME=str(writable), MPLCONFIGDIR=str(writable / "mpl"), XDG_CACHE_HOME=str(writable / "cache"))
    if os.geteuid() == 0:
        try:
            nobody = pwd.getpwnam("nobody")
        except KeyError:
            pytest.skip("running as root and there is no user 'nobody' to read the folder without write access")
        os.chown(writable, nobody.pw_uid, nobody.pw_gid)
        if shutil.which("setpriv"):
            prefix = ["setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups"]
            kw = {"env": env}
        else:
            prefix, kw = [], {"env": env, "user": nobody.pw_uid, "group": nobody.pw_gid, "extra_groups": []}
        # nobody needs to read this Python and explore3d: not so when the checkout (or its virtual
        # environment) sits under a folder only its owner can enter, such as a mktemp -d folder
        probe = subprocess.run([*prefix, sys.executable, "-c", "import explore3d"], capture_output=True, text=True,
                               timeout=120, **kw)
        if probe.returncode != 0:
            pytest.skip(f"the user nobody cannot run {sys.executable} with explore3d (a parent folder is private "
                        f"to its owner?): {(probe.stderr.strip().splitlines() or ['no output'])[-1]}")
        return prefix, kw, lambda: None
    dirs = [folder, *[p for p in folder.rglob("*") if p.is_dir()]]
    for p in dirs:
        p.chmod(0o555)
    return [], {"env": env}, lambda: [p.chmod(0o755) for p in dirs]


def _report(prefix, *argv, **kw):
    """``explore3d sweep-report ARGV`` in a fresh process, run through ``prefix``."""
    return subprocess.run([*prefix, sys.executable, "-m", "explore3d", "sweep-report", *map(str, argv)],
                          capture_output=True, text=True, timeout=120, **kw)


def test_report_of_a_read_only_sweep_folder(junk, shared_dir):
    folder = shared_dir / "sweep"
    for name in junk:  # two failed rows, no simulation
        assert main(["sweep", name, "--out", str(folder), "-q"]) == 1
    for p in folder.rglob("*"):
        p.chmod(0o755 if p.is_dir() else 0o644)
    assert {p.name for p in folder.iterdir()} == {DB_NAME, LOCK_NAME}  # the sweep's last close folded its log in
    elsewhere = shared_dir / "elsewhere"
    elsewhere.mkdir()
    prefix, kw, restore = _as_reader(folder, elsewhere)
    before = _snapshot(folder)
    try:
        r = _report(prefix, folder, **kw)  # the default output folder is inside the read-only folder
        line = _one_line(r.stderr)
        assert r.returncode == 1 and f"cannot write the report into {folder / 'report'}" in line, r.stderr
        assert "--out" in line
        r = _report(prefix, folder, "--out", elsewhere / "report", **kw)
        assert r.returncode == 0 and r.stderr == "", r.stderr
        assert _snapshot(folder) == before  # not a byte, not a -shm or -wal file
        # while a writer holds rows in the write-ahead log, the reader reads them too
        db = sqlite3.connect(folder / DB_NAME)
        db.execute("PRAGMA wal_autocheckpoint=0")
        db.execute("UPDATE runs SET reason = 'held in the log'")
        db.commit()
        try:
            r = _report(prefix, folder, "--out", elsewhere / "report2", "--no-thumbnails", **kw)
            assert r.returncode == 0, r.stderr
            assert (elsewhere / "report2" / "report.csv").read_text().count("held in the log") == 2
        finally:
            db.close()
    finally:
        restore()
    csv = (elsewhere / "report" / "report.csv").read_text().splitlines()
    assert len(csv) == 3 and all(",failed," in ln for ln in csv[1:])


# --- 4. every run failing ------------------------------------------------------------------------

def test_sweep_of_only_failing_objects_exits_1(junk, tmp_path, capsys):
    out = tmp_path / "all-failed"
    for _ in range(2):  # the rerun (nothing to run) says the same
        assert main(["sweep", *junk, "--out", str(out), "-q"]) == 1
        cap = capsys.readouterr()
        line = _one_line(cap.err)
        assert cap.out == "" and "every run failed" in line and "2 of 2" in line and "junk1.stl" in line, line
    assert [r["status"] for r in read_rows(out)] == ["failed", "failed"]
    assert main(["sweep", "--help"]) == 0
    assert "Exit codes" in capsys.readouterr().out


def test_sweep_with_some_failures_says_so_and_exits_0(setup, tmp_path, capsys):
    out = tmp_path / "some-failed"
    assert main(["sweep", setup["box"], setup["junk"][0], *setup["grid"], "--out", str(out), "-q"]) == 0
    cap = capsys.readouterr()
    line = _one_line(cap.err, prefix="explore3d: warning: ")
    assert cap.out == "" and "1 of 2" in line and "junk1.stl" in line, line
    assert sorted(r["status"] for r in read_rows(out)) == ["failed", "ok"]


# --- 5. workers die with their sweep -------------------------------------------------------------

def test_sweep_workers_die_with_a_killed_sweep(setup, tmp_path):
    out = tmp_path / "orphans"
    argv = ["sweep", "cube", setup["junk"][0], *setup["grid"], "--out", str(out), "--workers", "2", "-q"]
    # the cube's worker hangs (it would outlive the test by far if it did not die with its parent); the
    # junk file fails in the sweep's own process, before any worker
    proc = subprocess.Popen([sys.executable, "-m", "explore3d", *argv], start_new_session=True,
                            env=_env(EXPLORE3D_SWEEP_FAULT="hang:cube"), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        parent = psutil.Process(proc.pid)
        deadline = time.monotonic() + 60
        workers = []
        while not workers and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            workers = [c for c in _alive(parent.children()) if "from multiprocessing.spawn" in " ".join(c.cmdline())]
        assert len(workers) == 1, "the sweep's worker did not start"
        time.sleep(1.0)  # let them import and run (one killed sooner ends at its start: its parent is gone)
        family = _alive(parent.children(recursive=True))
        _kill_sweep_and_check_family(proc, family)
    finally:
        _reap_group(proc)
    assert main(argv) == 0  # the rerun completes the sweep
    assert {r["object"]: r["status"] for r in read_rows(out)} == {"cube": "ok", setup["junk"][0]: "failed"}


def test_wrap_pool_workers_die_with_a_killed_sweep(setup, tmp_path):
    out = tmp_path / "orphans-pool"
    argv = ["sweep", "cube", *setup["grid"], "--out", str(out), "--jobs-per-run", "2", "-q"]
    proc = subprocess.Popen([sys.executable, "-m", "explore3d", *argv], start_new_session=True, env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        parent = psutil.Process(proc.pid)
        deadline = time.monotonic() + 90
        pool = []
        while len(pool) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            # the run's wrap pool: processes forked by the sweep's worker (grandchildren of the sweep)
            pool = [g for c in _alive(parent.children()) for g in _alive(c.children())
                    if "from multiprocessing.spawn" in " ".join(c.cmdline())]
        assert len(pool) >= 2, "the run's wrap pool did not start"
        family = _alive(parent.children(recursive=True))
        _kill_sweep_and_check_family(proc, family)
    finally:
        _reap_group(proc)
