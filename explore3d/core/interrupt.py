"""Interrupts and kills: one place for what Ctrl-C, a killed parent and an optional import need.

* :func:`sigint_handler` (installed by the command line for the length of ``main``): the first
  SIGINT sets :data:`INTERRUPTED` and raises KeyboardInterrupt; later ones are ignored (the run is
  already unwinding), so no ``__del__`` or ``finally`` block is hit by a second one.
  :func:`check_interrupt` raises KeyboardInterrupt when the flag is set: an interrupt that C
  code or a ``__del__`` swallowed is still honoured at the next check.
* :func:`import_optional` imports an optional package (open3d, ray); an ImportError or OSError
  caused by an interrupt (KeyboardInterrupt in its cause/context chain, or the flag set) is
  re-raised as KeyboardInterrupt, never taken for "package missing".
* :func:`init_pool_worker` (the initializer of the exploration's worker processes): the worker
  dies with its parent (:func:`explore3d.core.lifeline.die_with_parent`) and ignores SIGINT (the parent handles Ctrl-C and tears
  the pool down), so a worker prints nothing.  :func:`sigint_blocked` blocks SIGINT in the
  forking thread so a child never runs the parent's handler before its initializer.
* :func:`deferred_signals`: SIGINT and SIGTERM that arrive inside the block take effect at its
  end (a run's output folder is switched to the new set of files inside one).
"""
from __future__ import annotations

import contextlib
import importlib
import os
import signal
import threading

from explore3d.core.lifeline import die_with_parent

__all__ = ["INTERRUPTED", "check_interrupt", "deferred_signals", "import_optional", "init_pool_worker",
           "interrupt_caused", "pid_alive", "sigint_blocked", "sigint_handler"]

#: Set by :func:`sigint_handler` when SIGINT arrived (one-element list: module-level mutable flag).
INTERRUPTED = [False]


def sigint_handler(signum, frame):
    """The command line's SIGINT handler: the first raises KeyboardInterrupt, later ones are ignored."""
    if INTERRUPTED[0]:
        return
    INTERRUPTED[0] = True
    raise KeyboardInterrupt


def check_interrupt() -> None:
    """Raise KeyboardInterrupt if a SIGINT arrived under :func:`sigint_handler` (none: no-op)."""
    if INTERRUPTED[0]:
        raise KeyboardInterrupt


def interrupt_caused(exc: BaseException) -> bool:
    """Whether ``exc`` came from an interrupt: a KeyboardInterrupt in its ``__cause__`` /
    ``__context__`` chain, or SIGINT seen by :func:`sigint_handler`."""
    seen = set()
    stack = [exc]
    while stack:
        e = stack.pop()
        if e is None or id(e) in seen:
            continue
        seen.add(id(e))
        if isinstance(e, KeyboardInterrupt):
            return True
        stack += [e.__cause__, e.__context__]
    return INTERRUPTED[0]


def import_optional(name: str):
    """``import name`` for an optional package; returns the module.

    Raises:
        ImportError, OSError: the package cannot be imported (callers fall back or name the fix).
        KeyboardInterrupt: the import failed because of an interrupt (:func:`interrupt_caused`):
            Ctrl-C during a slow first import is never taken for a missing package.
    """
    try:
        return importlib.import_module(name)
    except (ImportError, OSError) as exc:
        if interrupt_caused(exc):
            raise KeyboardInterrupt from None
        raise


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this machine (a zombie counts as gone on Linux)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    except OSError:
        return False
    try:  # a zombie (killed, not yet reaped by its parent) is dead for our purposes
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


def init_pool_worker(parent_pid: int) -> None:
    """Set up a worker process of the parent ``parent_pid``: it dies when the parent dies (at once
    on Linux, within about half a second elsewhere) and ignores SIGINT (the parent handles Ctrl-C)."""
    with contextlib.suppress(ValueError, OSError, AttributeError):  # not the main thread / no signals
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(ValueError, OSError, AttributeError):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked by sigint_blocked
    die_with_parent(parent_pid)


@contextlib.contextmanager
def sigint_blocked():
    """Block SIGINT in this thread for the block (processes forked inside inherit the mask, so they
    never run the parent's handler; :func:`init_pool_worker` ignores and unblocks it).  A SIGINT
    sent meanwhile is delivered at the block's end.  No-op where ``pthread_sigmask`` is missing."""
    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None:
        yield
        return
    old = mask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def deferred_signals():
    """SIGINT and SIGTERM arriving inside the block are acted on at its end (KeyboardInterrupt /
    the previous handler / the default action), so the block is never cut short by them.  Only in
    the main thread (elsewhere Python cannot set handlers; the block then runs unprotected)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got = []
    sigs = [s for s in (signal.SIGINT, getattr(signal, "SIGTERM", None)) if s is not None]
    old = {}
    try:
        for s in sigs:
            old[s] = signal.signal(s, lambda signum, frame: got.append(signum))
    except (ValueError, OSError):
        for s, h in old.items():
            signal.signal(s, h)
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for s in dict.fromkeys(got):
            h = old[s]
            if callable(h):
                h(s, None)
            elif h == signal.SIG_DFL:
                if s == signal.SIGINT:
                    raise KeyboardInterrupt
                os.kill(os.getpid(), s)
