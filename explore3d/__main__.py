"""``python -m explore3d``: the command line (see :mod:`explore3d.cli`)."""
import os
import signal
import sys


def _interrupted_early(signum, frame):
    """Ctrl-C before :func:`explore3d.cli.main` took over (while the command line imports): nothing
    has started, so say the one line and leave."""
    sys.stderr.write("explore3d: error: interrupted\n")
    sys.stderr.flush()
    os._exit(130)


signal.signal(signal.SIGINT, _interrupted_early)

from .cli import main  # noqa: E402 -- after the handler: an interrupt while importing prints one line

code = main()
if code == 130:  # interrupted: main has cleaned up and said so; skip the interpreter's teardown, where
    for stream in (sys.stdout, sys.stderr):  # objects the interrupt left half-made could still speak
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(130)
sys.exit(code)
