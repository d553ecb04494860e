"""One progress display per command, on stderr.

A command's work is a counted part (a run's wraps, a grasp grade's grasps) followed by labelled
steps (reconstructing, scoring, writing).  :class:`Progress` shows both on one bar whose total is
fixed when the counted part starts: the counted part's *planned maximum* (an exploration's planned
wraps plus the most its top search and probe rounds can add:
:func:`explore3d.strategy.explore.most_wraps`) plus one unit per labelled step.  A run that stops
early (a probe round that cannot change the estimate is skipped) leaves the bar short of its end
until :meth:`Progress.finish`, so the bar never shows 100% before the command is done; the
counted part's total grows only when the work outgrows its maximum (a persistent world repeats
each wrap after which the object moved, once).

On a terminal the bar is a tqdm bar, and the ``explore3d`` logger's console records are written
above it (``tqdm.write``, as :func:`tqdm.contrib.logging.logging_redirect_tqdm` does), never onto it.  When stderr is not a
terminal (a log file, a pipe, CI) there is no bar and no carriage return: one line per phase as
it starts.  ``enabled=False`` (``-q``) shows nothing.
"""
from __future__ import annotations

import contextlib
import logging
import sys

from explore3d.core.quiet import STDERR

log = logging.getLogger(__name__)

__all__ = ["Progress", "RUN_STEPS"]

#: the labelled steps of ``explore3d run`` after its wraps (:func:`explore3d.app.pipeline.run`,
#: :func:`explore3d.app.report.run_and_report`)
RUN_STEPS = ("reconstructing", "scoring", "writing")
#: the bar: the phase with the counted part's "done of at most total units", the percentage over the whole command
BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]"


class Progress:
    """The progress display of one command (module docstring); a context manager.

    Args:
        steps: the labelled steps that follow the counted part, in order (one bar unit each).
        unit: what the counted part counts ("wrap", "grasp").
        stream: where to write (default: the terminal's stderr, :data:`~explore3d.core.quiet.STDERR`).
        enabled: False shows nothing (``-q``).
        prog: the prefix of the line-per-phase display.
    """

    def __init__(self, steps=(), unit: str = "wrap", stream=None, enabled: bool = True, prog: str = "explore3d"):
        self.steps = tuple(steps)
        self.unit = unit
        self.stream = STDERR if stream is None else stream
        self.enabled = bool(enabled)
        isatty = getattr(self.stream, "isatty", None)
        self.tty = self.enabled and bool(isatty and isatty())
        self.prog = prog
        self.phase = None
        self.done = 0
        self.total = None  # the counted part's total (None until the first update)
        self._bar = None
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> "Progress":
        if self.tty:
            from tqdm import tqdm  # start-up: kept out of explore3d --help's

            self._bar = tqdm(total=2 + len(self.steps), file=self.stream, leave=False, bar_format=BAR_FORMAT,
                             dynamic_ncols=True)
            self._stack.callback(self._redirect_logging())
        return self

    def _redirect_logging(self):
        """The ``explore3d`` logger's console handlers write through the bar (``tqdm.write``: the
        bar is cleared, the record printed on its own line, the bar drawn again), as
        :func:`tqdm.contrib.logging.logging_redirect_tqdm` does for handlers on ``sys.stderr``
        (the command line's handler writes to :data:`~explore3d.core.quiet.STDERR`, which that does
        not recognise).  Returns the function that puts the handlers back."""
        logger = logging.getLogger("explore3d")
        bar, stream = self._bar, self.stream
        console = (sys.stderr, sys.stdout, stream, STDERR)

        class BarHandler(logging.Handler):
            def emit(self, record):
                try:
                    bar.write(self.format(record), file=stream)
                except Exception:  # noqa: BLE001 - logging's own convention
                    self.handleError(record)

        swapped = []
        for i, h in enumerate(list(logger.handlers)):
            if isinstance(h, logging.StreamHandler) and not isinstance(h, logging.FileHandler) and any(
                    h.stream is c for c in console):
                b = BarHandler(h.level)
                b.setFormatter(h.formatter)
                logger.handlers[i] = b
                swapped.append((i, h))

        def restore():
            for i, h in swapped:
                logger.handlers[i] = h
        return restore

    def __exit__(self, *exc) -> None:
        self._stack.close()
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __call__(self, done: int, total: int | None = None, phase: str | None = None) -> None:
        """The counted part's progress: ``done`` of at most ``total`` (None: unchanged) in ``phase``
        (None: unchanged); the signature an exploration's ``progress`` takes."""
        self.update(done, total, phase)

    def update(self, done: int, total: int | None = None, phase: str | None = None) -> None:
        if phase in self.steps:  # a run calls its labelled steps through the same callable
            self.step(phase)
            return
        self.done = int(done)
        if total is not None or self.total is not None:
            self.total = max(int(self.total if total is None else total), self.done)
        self._show(phase)
        log.info("%s%s", self.phase, "" if self.total is None else f": {self._counted()}")

    def step(self, name: str) -> None:
        """Start the labelled step ``name`` (one of ``steps``): the counted part is over."""
        if name not in self.steps:
            raise ValueError(f"unknown progress step {name!r}; this command's steps: {', '.join(self.steps)}")
        if self.total is None:
            self.total = max(self.done, 1)
        self._show(name)
        log.info("%s", name)

    def finish(self) -> None:
        """The command is done: the bar shows 100% and closes."""
        if self._bar is not None:
            self._bar.total = self._bar.n = self._units()[1]
            self._bar.refresh()

    # --- display ---

    def _units(self) -> tuple[float, int]:
        """(position, total) of the bar: the counted part as one unit per planned item, each
        labelled step one unit more, and a last unit only :meth:`finish` fills."""
        total = (self.total or 1) + len(self.steps) + 1
        if self.phase in self.steps:
            return float((self.total or 1) + self.steps.index(self.phase)), total
        return float(self.done), total

    def _counted(self) -> str:
        if self.total is None:
            return ""
        return f"{self.done} of at most {self.total} {self.unit}s"

    def _show(self, phase: str | None) -> None:
        if not self.enabled:
            return
        changed = phase is not None and phase != self.phase
        if phase is not None:
            self.phase = phase
        counted = "" if self.phase in self.steps or self.total is None else f" ({self._counted()})"
        if self._bar is not None:
            n, total = self._units()
            self._bar.total = total
            self._bar.n = n
            self._bar.set_description_str(f"{self.phase or ''}{counted}", refresh=False)
            self._bar.refresh()
        elif changed:  # no terminal: a line per phase
            print(f"{self.prog}: {self.phase}{counted}", file=self.stream, flush=True)
