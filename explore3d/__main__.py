"""``python -m explore3d`` and the ``explore3d`` program: the command line (see :mod:`explore3d.app.cli`)."""
import os
import signal
import sys


def _interrupted_early(signum, frame):
    """Ctrl-C before :func:`explore3d.app.cli.main` took over (while the command line imports): nothing
    has started, so say the one line and leave."""
    sys.stderr.write("explore3d: error: interrupted\n")
    sys.stderr.flush()
    os._exit(130)


def entry() -> None:
    """Run :func:`explore3d.app.cli.main` as the program and exit with its code.  An interrupt while the
    command line imports prints the one line; after an interrupted run (130: main has cleaned up
    and said so) it leaves by ``os._exit``, skipping the interpreter's teardown, where objects the
    interrupt left half-made could still print or the interpreter re-kill itself with SIGINT."""
    signal.signal(signal.SIGINT, _interrupted_early)
    from explore3d.app.cli import main  # start-up: after the SIGINT handler is in place

    code = main()
    if code == 130:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(130)
    sys.exit(code)


if __name__ == "__main__":
    entry()
