"""Interrupted, killed or failed: ``explore3d run`` says one line and its output folder holds one
run's complete set of files or none (explore3d.core.io.StagedFolder, explore3d.core.interrupt).

The runs are real command-line processes (``python -m explore3d``) in a session of their own, so
Ctrl-C is sent as a terminal sends it: SIGINT to the whole process group, the workers included.
"""
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from explore3d.core.io import STAGING_PREFIX
from explore3d.app.report import RUN_FILES, WRITE_PAUSE_ENV

REPO = str(Path(__file__).resolve().parents[1])

#: A small 3D run on two worker processes (6 wraps, about 5 s here): enough wraps to interrupt.
RUN = ["run", "cube", "--mode", "3d", "--directions", "2", "--angles", "1", "--probes", "0", "--jobs", "2",
       "--no-pictures", "-q"]
#: The same run told a wrong rough bound: no contact, exit 1 (a failed run).
NO_CONTACT = ["--centre", "1,0,0", "--radius", "0.06"]


def _env(**extra):
    return {**os.environ, "PYTHONPATH": os.pathsep.join([REPO, *extra.pop("PREPEND", [])]), **extra}


def _start(out, *argv, **env):
    return subprocess.Popen([sys.executable, "-m", "explore3d", *RUN, "--out", str(out), *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(**env),
                            start_new_session=True)


def _finish(proc, timeout=60):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def _run(out, *argv, **env):
    return _finish(_start(out, *argv, **env))


def _wait_for(cond, timeout=40.0, what="the condition", step=0.02):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return
        time.sleep(step)
    raise AssertionError(f"timed out waiting for {what}")


def _snapshot(folder: Path) -> dict:
    """Every entry of ``folder``: name -> sha256 of a file, or 'dir'."""
    return {p.name: ("dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(folder.iterdir())} if folder.exists() else {}


def _one_run_or_none(folder: Path, earlier: dict) -> str:
    """Assert ``folder`` holds the earlier run's set untouched, one complete set (its report.json
    lists exactly the files beside it), or no run files; nothing hidden.  Returns which."""
    now = _snapshot(folder)
    hidden = [n for n in now if n.startswith(".")]
    assert not hidden, hidden
    if not now:
        return "none"
    if now == earlier:
        return "earlier"
    assert "report.json" in now, now
    report = json.loads((folder / "report.json").read_text())
    assert sorted(now) == report["files"], (sorted(now), report["files"])
    return "new"


def _assert_interrupted(code, err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 130, (code, err)
    assert lines == ["explore3d: error: interrupted"], err
    assert "Traceback" not in err and "Exception ignored" not in err


def _dead_pid() -> int:
    """The pid of a process that has exited (a killed writer's, for the leftovers' names)."""
    r = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                       check=True)
    return int(r.stdout)


def _ctrl_c(proc):
    """SIGINT to the run's process group, as a terminal's Ctrl-C."""
    os.killpg(proc.pid, signal.SIGINT)


def _workers(proc):
    try:
        return psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


@pytest.fixture(scope="module")
def earlier_run(tmp_path_factory):
    """A complete run's folder (its snapshot is what an interrupted run must leave)."""
    out = tmp_path_factory.mktemp("earlier") / "o"
    code, _, err = _run(out)
    assert code == 0, err
    return out


def _copy(src: Path, dst: Path) -> dict:
    import shutil

    shutil.copytree(src, dst)
    return _snapshot(dst)


@pytest.mark.parametrize("moment", ["start", "early", "workers", "wraps", "writing"])
def test_ctrl_c_exits_130_with_one_line_and_leaves_one_run(tmp_path, earlier_run, moment):
    """Ctrl-C at a few moments of a run into the folder of an earlier complete run: exit 130, the one
    line, no traceback (parent or worker), and the folder holds the earlier set (or a complete new one
    when the interrupt came after the switch), never a partial mix, nothing hidden; no worker lives on."""
    out = tmp_path / "o"
    earlier = _copy(earlier_run, out)
    env = {WRITE_PAUSE_ENV: "30"} if moment == "writing" else {}
    proc = _start(out, **env)
    if moment == "start":  # while the command line imports (Python itself is up in about 0.05 s)
        time.sleep(0.3)
    elif moment == "early":  # after the imports, before or while the simulation starts
        time.sleep(1.0)
    elif moment in ("workers", "wraps"):  # as the workers start (before they hold a task), or in the wraps
        _wait_for(lambda: len(_workers(proc)) >= 2, what="the two workers", step=0.002)
        time.sleep(0.0 if moment == "workers" else 1.5)
    else:  # the estimate written into the staging folder, report.json and the switch still to come
        _wait_for(lambda: any((p / "estimate.urdf").exists() for p in out.glob(STAGING_PREFIX + "*")),
                  what="the staged estimate")
    workers = _workers(proc)
    _ctrl_c(proc)
    code, _, err = _finish(proc)
    _assert_interrupted(code, err)
    assert _one_run_or_none(out, earlier) == "earlier"  # every moment here comes before the switch
    gone, alive = psutil.wait_procs(workers, timeout=5)
    assert not alive, alive


def test_interrupt_during_an_optional_import_is_not_a_missing_package(tmp_path):
    """Ctrl-C landing in the first ``import open3d`` (here an open3d that is interrupted while it loads
    and then reports an ImportError, as a failed library load does) stops the run with exit 130; it is
    not taken for "open3d missing" with the run going on to exit 0."""
    fake = tmp_path / "fake"
    (fake / "open3d").mkdir(parents=True)
    (fake / "open3d" / "__init__.py").write_text(
        "import os, signal, time\n"
        "try:\n"
        "    os.kill(os.getpid(), signal.SIGINT)  # the user's Ctrl-C, during the slow library load\n"
        "    time.sleep(2)\n"
        "except BaseException:\n"
        "    pass\n"
        "raise ImportError('libopen3d.so: cannot open shared object file')\n")
    out = tmp_path / "o"
    code, _, err = _run(out, PREPEND=[str(fake)])
    _assert_interrupted(code, err)
    assert _one_run_or_none(out, {}) == "none"


def test_import_optional_reraises_an_interrupt_in_the_import_error_chain(tmp_path, monkeypatch):
    """Library use (no command-line handler): an ImportError whose cause or context is a
    KeyboardInterrupt is re-raised as KeyboardInterrupt; a plain ImportError stays one."""
    from explore3d.core.interrupt import import_optional

    for name, body in [("e3d_fake_cause", "try:\n    raise KeyboardInterrupt\nexcept KeyboardInterrupt as e:\n"
                                          "    raise ImportError('load failed') from e\n"),
                       ("e3d_fake_context", "try:\n    raise KeyboardInterrupt\nexcept BaseException:\n"
                                            "    raise ImportError('load failed') from None\n"),
                       ("e3d_fake_missing", "raise ImportError('libusb-1.0.so.0: cannot open')\n")]:
        (tmp_path / f"{name}.py").write_text(body)
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("e3d_fake_cause", "e3d_fake_context"):
        with pytest.raises(KeyboardInterrupt):
            import_optional(name)
    with pytest.raises(ImportError, match="libusb"):
        import_optional("e3d_fake_missing")


def test_sigkill_of_the_parent_kills_its_workers_and_the_next_run_cleans_up(tmp_path):
    """SIGKILL of a run on two workers during the wraps: no worker survives it by more than a few
    seconds; the killed run's staging folder stays behind, and the next run into the folder removes
    it and completes."""
    out = tmp_path / "o"
    proc = _start(out)
    _wait_for(lambda: len(_workers(proc)) >= 2, what="the two workers")
    time.sleep(0.5)
    workers = _workers(proc)
    assert len(workers) >= 2
    proc.kill()
    proc.communicate(timeout=10)
    gone, alive = psutil.wait_procs(workers, timeout=5)
    assert not alive, f"workers outlived their killed parent: {alive}"
    left = [p.name for p in out.iterdir()]
    assert left and all(n.startswith(STAGING_PREFIX) for n in left), left  # the killed run's staging
    code, _, err = _run(out)
    assert code == 0, err
    assert _one_run_or_none(out, {}) == "new"


def test_sigkill_while_writing_leaves_the_earlier_set_and_the_next_run_cleans_up(tmp_path, earlier_run):
    """SIGKILL while the files are written: the folder still holds the earlier complete set beside
    the killed run's staging folder; an old-style ``.overview.*.part.png`` (no pid) and a part file of
    a dead writer are removed by the next run, which completes."""
    out = tmp_path / "o"
    earlier = _copy(earlier_run, out)
    dead_pid = _dead_pid()
    legacy, dead_part = out / ".overview.k2j4x9_q.part.png", out / f".signed_distance.{dead_pid}.a1b2c3d4.part.png"
    foreign = out / "notes.txt"  # not a run file: never touched
    for p in (legacy, dead_part, foreign):
        p.write_bytes(b"x")
    proc = _start(out, **{WRITE_PAUSE_ENV: "30"})
    _wait_for(lambda: any((p / "estimate.urdf").exists() for p in out.glob(STAGING_PREFIX + "*")),
              what="the staged estimate")
    proc.kill()
    proc.communicate(timeout=10)
    now = _snapshot(out)
    staging = [n for n in now if n.startswith(STAGING_PREFIX)]
    assert len(staging) == 1, now
    assert {n: h for n, h in now.items() if n not in staging and n not in (legacy.name, dead_part.name,
                                                                          foreign.name)} == earlier
    code, _, err = _run(out)
    assert code == 0, err
    foreign.unlink()
    assert _one_run_or_none(out, earlier) == "new"


def test_a_failed_run_leaves_no_estimate_of_an_earlier_run(tmp_path, earlier_run):
    """A run that makes no contact (wrong rough bound: exit 1, one line) into the folder of an
    earlier complete run: its report.json says why it failed, and none of the earlier run's estimate,
    URDF or free space is left beside it."""
    out = tmp_path / "o"
    earlier = _copy(earlier_run, out)
    assert {"estimate.obj", "estimate.urdf", "free_space.npz"} <= set(earlier)
    assert set(json.loads((out / "report.json").read_text())["files"]) <= RUN_FILES
    code, _, err = _run(out, *NO_CONTACT)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 1 and len(lines) == 1 and lines[0].startswith("explore3d: error: no contacts"), err
    report = json.loads((out / "report.json").read_text())
    assert "no contact" in report["error"] and report["n_contacts"] == 0
    assert sorted(_snapshot(out)) == ["report.json"] + (["points.ply"] if report["n_points"] else [])


@pytest.mark.parametrize("kill_after", range(5))
def test_a_switch_killed_at_any_step_is_finished_by_the_next_run(tmp_path, monkeypatch, kill_after):
    """The switch of a folder to a new set, killed after ``kill_after`` of its moves (os.replace made
    to fail there, as a SIGKILL would stop it): the folder then has a report.json only beside one
    complete set, and the next run's cleaning (explore3d.core.io.stale_leftovers) finishes the switch:
    exactly the new set, the earlier run's other files gone, no staging folder left."""
    from explore3d.core import io

    out = tmp_path / "o"
    out.mkdir()
    earlier = {"report.json": "old report", "estimate.obj": "old", "estimate.urdf": "old", "views.png": "old"}
    new = {"report.json": "new report", "estimate.stl": "new", "estimate.urdf": "new", "points.ply": "new"}
    for n, t in earlier.items():
        (out / n).write_text(t)
    staged = io.StagedFolder(out, RUN_FILES).__enter__()
    for n, t in new.items():
        (staged.path / n).write_text(t)
    real, calls = os.replace, []

    def replace(a, b):
        if Path(b).parent == out:  # a move into the folder (not the journal's own atomic write)
            if len(calls) >= kill_after:
                raise OSError(f"killed before moving {b}")
            calls.append(b)
        real(a, b)

    monkeypatch.setattr(io.os, "replace", replace)
    if kill_after < len(new):
        with pytest.raises(OSError):
            staged.commit()
    else:
        staged.commit()
    monkeypatch.setattr(io.os, "replace", real)
    now = {p.name: p.read_text() for p in out.iterdir() if p.is_file()}
    if "report.json" in now:  # the marker is only ever beside one complete set
        assert now in (earlier, new), now
    if kill_after >= len(new):
        assert now == new and not [p for p in out.iterdir() if p.is_dir()]
        return
    stage = staged.path.rename(out / f"{io.STAGING_PREFIX}{_dead_pid()}-killed")  # its writer is gone
    cleaned = io.stale_leftovers(out, RUN_FILES)
    assert cleaned == [stage.name]
    assert {p.name: p.read_text() for p in out.iterdir()} == new


def test_main_clears_its_interrupt_flag(monkeypatch):
    """An interrupted in-process ``main`` (Ctrl-C in a notebook) leaves no flag behind: library calls
    afterwards are not taken for interrupted (check_interrupt passes)."""
    from explore3d.app import cli
    from explore3d.core.interrupt import INTERRUPTED, check_interrupt

    def interrupted(args):
        os.kill(os.getpid(), signal.SIGINT)  # through the command line's handler, as a real Ctrl-C
        time.sleep(5)
        return 0

    monkeypatch.setattr(cli, "cmd_objects", interrupted)  # build_parser binds the command at call time
    assert cli.main(["objects"]) == 130
    assert INTERRUPTED[0] is False
    check_interrupt()

