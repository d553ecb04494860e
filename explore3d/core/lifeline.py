"""Worker processes that die with their parent, SIGKILL of the parent included."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

#: prctl option: the signal the kernel sends this process when its parent (thread) dies.
_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int | None = None) -> str:
    """Make this process end when its parent does (however the parent ends).

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills this process when the thread
    that started it exits); elsewhere, or if prctl fails: a daemon thread that polls the parent's
    pid every 0.5 s and exits the process when it changes.  ``parent_pid``: the parent's pid as the
    parent saw it (default: ``os.getppid()`` now); if the parent already died before this call,
    the process ends here.  Returns ``"prctl"`` or ``"thread"`` (how it is watched)."""
    parent = os.getppid() if parent_pid is None else int(parent_pid)
    how = "thread"
    if sys.platform.startswith("linux"):
        try:
            import ctypes  # optional extra of the platform: Linux's prctl through libc

            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0:
                how = "prctl"
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent died before the kernel was told to watch it
        os._exit(1)
    if how == "thread":

        def watch():
            while os.getppid() == parent:
                time.sleep(0.5)
            os._exit(1)

        threading.Thread(target=watch, name="explore3d-lifeline", daemon=True).start()
    return how
