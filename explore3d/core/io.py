"""Atomic file output: a killed run never leaves a half-written file under a final name, and a
run's set of files replaces the previous set in its folder as a whole (:class:`StagedFolder`)."""
from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import shutil
import tempfile
from pathlib import Path

from explore3d.core.interrupt import deferred_signals, pid_alive

log = logging.getLogger(__name__)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``.

    The temporary file keeps ``path``'s suffix (so writers that infer the format from the
    suffix work) and is removed if the body raises.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # the writer's pid in the name: stale_leftovers tells a killed writer's part from a live one's
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.{os.getpid()}.", suffix=f".part{path.suffix}",
                                   dir=path.parent)
    except OSError as exc:  # name the file the user asked for, not the hidden temporary
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    os.close(fd)
    tmp = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; final files get the usual permissions
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and exc.filename == str(tmp):  # the user's file, not the temporary
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def _json_default(o):
    import numpy as np  # start-up: the core stays light (explore3d --help loads it)

    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if hasattr(o, "value"):  # enums
        return o.value
    if isinstance(o, (set, frozenset, tuple)):
        return list(o)
    return str(o)


def json_text(obj) -> str:
    """``obj`` as indented JSON text ending in a newline (numpy arrays and scalars, enums and
    tuples converted); the one JSON writer of report.json, the command line and the scripts."""
    return json.dumps(obj, indent=2, default=_json_default) + "\n"


# --- a folder's set of files, replaced as a whole ------------------------------------------------------

#: The hidden staging folders a run writes into, inside the output folder: ``.staging-<pid>-<random>``.
STAGING_PREFIX = ".staging-"
#: The journal of a staging folder whose switch has begun: the names it holds, one a line.
_JOURNAL = ".commit"
_STAGING_RE = re.compile(r"^" + re.escape(STAGING_PREFIX) + r"(\d+)-")
_PART_RE = re.compile(r"^\.([^.]+)\.(?:(\d+)\.)?[^.]+\.part(?:\.[^.]*)?$")  # atomic_path's temporaries


@contextlib.contextmanager
def exclusive_lock(path, waiting: str | None = None):
    """Hold an exclusive ``flock`` on ``path`` (a folder, or a file, created if missing) while in
    the block; wait while another process holds it (logging ``waiting`` at INFO first, if given).
    POSIX; elsewhere, on a file system without locks, or where the file cannot be created, no
    lock."""
    try:
        import fcntl  # optional extra of the platform: POSIX only
    except ImportError:
        fcntl = None
    path = Path(path)
    fd = None
    if fcntl is not None:
        with contextlib.suppress(OSError):  # cannot be created (a read-only folder): unlocked
            fd = os.open(path, os.O_RDONLY if path.is_dir() else os.O_RDONLY | os.O_CREAT, 0o644)
    if fd is None:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if waiting:
                log.info(waiting)
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # a file system without locks: unlocked, as elsewhere
            pass
        yield
    finally:
        os.close(fd)  # releases the lock


def _finish_switch(staging: Path, folder: Path, owned, last: str) -> None:
    """Make ``folder``'s ``owned`` names exactly the ones of the journal of ``staging``: remove
    ``last`` (the set's marker) while it is still to come, the owned names the new set lacks, move
    the new files in, ``last`` last, then remove ``staging``.  Idempotent: repeating it after a
    kill at any step finishes the same switch."""
    names = [n for n in (staging / _JOURNAL).read_text(encoding="utf-8").splitlines() if n]
    if (staging / last).exists():
        with contextlib.suppress(FileNotFoundError):
            (folder / last).unlink()  # from here on folder has no marker until the new set is in
    for n in sorted(set(owned) - set(names)):
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, PermissionError):
            (folder / n).unlink()
    for n in [n for n in names if n != last] + ([last] if last in names else []):
        if (staging / n).exists():
            os.replace(staging / n, folder / n)
    shutil.rmtree(staging, ignore_errors=True)


def stale_leftovers(folder, owned, last: str = "report.json") -> list[str]:
    """Clean what killed runs left in ``folder`` and return the names removed or finished:

    * staging folders (``.staging-<pid>-*``) of processes no longer alive: one whose switch had
      begun (it holds its journal) is finished (the folder then holds that run's complete set),
      any other is removed (the folder still holds the set from before that run);
    * :func:`atomic_path` temporaries ``.<stem>.<pid>.<random>.part<suffix>`` of an ``owned`` stem
      whose writer is no longer alive, and those without a pid (written by older explore3d).

    Staging folders and temporaries of live processes (another run into the same folder) are
    kept.  A pid reused by a new process keeps its leftovers until a later run."""
    folder = Path(folder)
    stems = {Path(n).stem for n in owned}
    done = []
    for p in sorted(folder.iterdir()):
        m = _STAGING_RE.match(p.name)
        if m and p.is_dir() and not pid_alive(int(m.group(1))):
            if (p / _JOURNAL).is_file():
                _finish_switch(p, folder, owned, last)
            else:
                shutil.rmtree(p, ignore_errors=True)
            done.append(p.name)
            continue
        m = _PART_RE.match(p.name)
        if m and m.group(1) in stems and p.is_file() and (m.group(2) is None or not pid_alive(int(m.group(2)))):
            with contextlib.suppress(OSError):
                p.unlink()
            done.append(p.name)
    return done


class StagedFolder:
    """A run's files written into a hidden staging folder inside ``folder`` (same file system) and
    switched in as a whole by :meth:`commit`.

    Guarantees: ``folder`` never mixes two runs' files among the ``owned`` names (the set the
    writer can produce).  Before :meth:`commit` it holds the earlier set untouched; after it, the
    new set exactly (owned names the new set lacks are removed).  The switch itself runs with
    SIGINT and SIGTERM deferred; a SIGKILL or power cut inside it leaves ``folder`` without
    ``last`` (the marker, e.g. report.json) and the staging folder's journal, from which the next
    :func:`stale_leftovers` (every new StagedFolder runs it) finishes the switch.  So: whenever
    ``last`` is in ``folder``, the owned names there are one run's complete set.

    Use it as a context manager: entering cleans ``folder``'s stale leftovers
    (:func:`stale_leftovers`, their names in :attr:`cleaned`) and makes the staging folder
    :attr:`path`, with SIGINT/SIGTERM deferred so an interrupt never leaves a staging folder
    behind; leaving without :meth:`commit` (an exception, an interrupt) calls :meth:`discard`,
    which removes the staging folder and leaves ``folder`` as it was.
    """

    def __init__(self, folder, owned, last: str = "report.json"):
        self.folder = Path(folder)
        self.owned, self.last = frozenset(owned) | {last}, last
        self.path = None
        self.cleaned: list[str] = []
        self.committed = False

    def __enter__(self):
        try:
            with deferred_signals():
                self.folder.mkdir(parents=True, exist_ok=True)
                with exclusive_lock(self.folder):  # two runs into one folder clean and switch it one at a time
                    self.cleaned = stale_leftovers(self.folder, self.owned, self.last)
                    self.path = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=self.folder))
        except BaseException:  # an interrupt deferred to the block's end, or a failure inside it
            self.discard()
            raise
        return self

    def __exit__(self, exc_type, exc, tb):
        if not self.committed:
            self.discard()

    def names(self) -> list[str]:
        """The files written into the staging folder so far (hidden temporaries left out)."""
        return sorted(p.name for p in self.path.iterdir() if p.is_file() and not p.name.startswith("."))

    def commit(self) -> list[str]:
        """Switch ``folder`` to the staged files (see the class); returns their names."""
        names = self.names()
        # two runs into one folder clean and switch it one at a time
        with deferred_signals(), exclusive_lock(self.folder):
            atomic_write_text(self.path / _JOURNAL, "".join(n + "\n" for n in names))
            _finish_switch(self.path, self.folder, self.owned | set(names), self.last)
            self.committed = True
        return names

    def discard(self) -> None:
        """Remove the staging folder unless its switch has begun (then the next run finishes it)."""
        if self.path is not None and not (self.path / _JOURNAL).exists():
            shutil.rmtree(self.path, ignore_errors=True)
