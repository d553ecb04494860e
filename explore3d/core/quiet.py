"""Keep PyBullet's C-level banners off the terminal: one helper for the command line, the scripts
and the library.

PyBullet's C++ code prints with ``printf`` straight to the process's file descriptors, past
Python's ``sys.stdout``/``sys.stderr``: ``pybullet build time: ...`` on fd 2 at ``import pybullet``,
``PyBullet: Constraint Solver: MLCP + Dantzig`` / ``switched solver`` on fd 1 when the solver is
switched, ``argv[0]=`` when a client connects, TinyRenderer messages when it renders.  A JSON
printed by ``explore3d table1 --json`` after them would not parse.

:func:`quiet_c_output` points fds 1 and 2 at /dev/null for a block (flushing Python's buffers
first) and, while it lasts, gives Python's ``sys.stdout``/``sys.stderr`` (when they write to
those descriptors) private copies of the original descriptors, so Python-level output (results,
errors, a progress bar written to :data:`STDERR`) still shows.  Blocks nest.  Processes forked
inside a block (the exploration's workers) inherit the silenced descriptors.
"""
from __future__ import annotations

import contextlib
import io
import os
import sys

__all__ = ["PYBULLET_BANNERS", "STDERR", "quiet_c_output"]

#: Text PyBullet's C code prints (seen with pybullet 3.2.7); none of it may reach a user's terminal.
PYBULLET_BANNERS = ("argv[0]=", "PyBullet: Constraint Solver", "switched solver", "pybullet build time",
                    "TinyRenderer", "startThreads")


class _CurrentStderr:
    """A file-like object that writes to whatever ``sys.stderr`` is at the time of the write
    (give it to progress bars and log handlers created outside a :func:`quiet_c_output` block)."""

    def write(self, s):
        return sys.stderr.write(s)

    def flush(self):
        sys.stderr.flush()

    def isatty(self):
        return bool(getattr(sys.stderr, "isatty", lambda: False)())

    @property
    def encoding(self):
        return getattr(sys.stderr, "encoding", "utf-8")


#: Writes to the current ``sys.stderr``; stays visible inside :func:`quiet_c_output`.
STDERR = _CurrentStderr()


def _fd_of(stream) -> int | None:
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):  # pytest's capture, io.StringIO, closed streams
        return None


@contextlib.contextmanager
def quiet_c_output():
    """Send everything written to file descriptors 1 and 2 by C code to /dev/null inside the
    block; Python's ``sys.stdout`` and ``sys.stderr`` keep writing to the original terminal or
    pipe.  Without real descriptors (embedded interpreters) it does nothing."""
    names = {1: "stdout", 2: "stderr"}
    for name in names.values():
        with contextlib.suppress(AttributeError, OSError, ValueError):
            getattr(sys, name).flush()
    try:
        saved = {fd: os.dup(fd) for fd in names}
    except OSError:
        yield
        return
    replaced = {}
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in names:
                os.dup2(null, fd)
        finally:
            os.close(null)
        for fd, name in names.items():
            stream = getattr(sys, name)
            if _fd_of(stream) == fd:  # a real stream on that descriptor: give it the original one
                copy = io.TextIOWrapper(os.fdopen(os.dup(saved[fd]), "wb", buffering=0),
                                        encoding=getattr(stream, "encoding", None) or "utf-8",
                                        errors=getattr(stream, "errors", None) or "strict",
                                        line_buffering=True, write_through=True)
                replaced[name] = (stream, copy)
                setattr(sys, name, copy)
        yield
    finally:
        for name, (orig, copy) in replaced.items():
            with contextlib.suppress(OSError, ValueError):
                copy.flush()
            setattr(sys, name, orig)
            with contextlib.suppress(OSError, ValueError):
                copy.close()
        for fd, s in saved.items():
            os.dup2(s, fd)
            os.close(s)

