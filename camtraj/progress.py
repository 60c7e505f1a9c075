"""Progress of one run, stage by stage: a small protocol and its terminal display.

A long job calls ``progress.stage(name, total)`` when a stage starts and
``progress.advance(n)`` as it finishes steps of it. Both are optional for a stage: one that
never calls ``advance`` (or gives no ``total``) still shows its name and its elapsed time, so a
stage module can adopt the protocol later, or only in part. Stage modules take the plain
``advance`` callback (``Callable[[int], None]``), or a :class:`Progress` when they have stages
of their own.

:class:`Silent` (the default everywhere) does nothing. :class:`TerminalProgress` draws one
status line on a terminal (tqdm): the stage's name, a bar when its size is known, and the
elapsed time, redrawn several times a second by a background thread even while a stage reports
nothing (a stage whose steps are all done but which goes on says "finishing"); the line is
cleared when the run ends. The command line uses it only when stderr is a
terminal and neither ``--quiet`` nor ``--json`` is given.

This module imports nothing heavy, so a command can show progress before it imports the
pipeline (USD, scipy), which takes a second or more.
"""

from __future__ import annotations

import sys
import threading
from types import TracebackType
from typing import Any, Protocol, TextIO

__all__ = ["Progress", "Silent", "TerminalProgress", "progress_for"]

REFRESH_S = 0.2
"""How often [s] the terminal line is redrawn while a stage runs."""


class Progress(Protocol):
    """What a stage may call to report its progress."""

    def stage(self, name: str, total: int | None = None, *, unit: str = "step") -> None:
        """Start stage ``name`` (ending the one before); ``total`` steps if known."""

    def advance(self, n: int = 1) -> None:
        """``n`` more steps of the current stage are done."""


class Silent:
    """Progress that shows nothing (library calls, batch workers, non-terminals)."""

    def stage(self, name: str, total: int | None = None, *, unit: str = "step") -> None:
        """Nothing to show."""

    def advance(self, n: int = 1) -> None:
        """Nothing to show."""

    def close(self) -> None:
        """Nothing to clear."""

    def __enter__(self) -> Silent:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_COUNTED = (
    "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {unit} [{elapsed_s:.1f} s{postfix}]"
)
_UNCOUNTED = "{desc}  {elapsed_s:.1f} s"


class TerminalProgress:
    """One status line on a terminal: ``LABEL: STAGE  43%|████   | 620/1440 frame [4.2 s]``.

    Args:
        label: What the run is about (the shot's file name).
        stream: Where to draw (a terminal).
        refresh_s: Redraw interval [s] of the background thread.
    """

    def __init__(self, label: str, *, stream: TextIO | None = None,
                 refresh_s: float = REFRESH_S) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.refresh_s = refresh_s
        self._bar: Any = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def stage(self, name: str, total: int | None = None, *, unit: str = "step") -> None:
        from tqdm import tqdm

        with self._lock:
            if self._stop.is_set():
                return
            if self._bar is not None:
                self._bar.close()
            counted = total is not None and total > 0
            # Made without drawing (a long delay), drawn only once it is ours to close: a stop
            # (Ctrl-C) inside the constructor after it drew would leave a bar nothing clears,
            # and the ERROR line would run on after it.
            bar = tqdm(
                total=total if counted else None,
                desc=f"{self.label}: {name}",
                unit=unit,
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
                mininterval=self.refresh_s,
                bar_format=_COUNTED if counted else _UNCOUNTED,
                delay=1e9,
            )
            self._bar = bar
            bar.delay = 0.0  # from here drawn as usual, and cleared by close
            bar.refresh()
        if self._thread is None:
            self._thread = threading.Thread(target=self._redraw, name="camtraj-progress",
                                            daemon=True)
            self._thread.start()

    def advance(self, n: int = 1) -> None:
        with self._lock:
            bar = self._bar
            if bar is not None:
                bar.update(n)
                if bar.total is not None and bar.n >= bar.total and not bar.postfix:
                    bar.set_postfix_str("finishing", refresh=False)  # steps done, stage not

    def _redraw(self) -> None:
        while not self._stop.wait(self.refresh_s):
            with self._lock:
                if self._bar is not None:
                    self._bar.refresh()

    def close(self) -> None:
        """End the last stage and clear the line (idempotent)."""
        self._stop.set()
        with self._lock:
            if self._bar is not None:
                self._bar.close()
                self._bar = None
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)  # a stalled terminal must not hang the exit

    def __enter__(self) -> TerminalProgress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def progress_for(label: str, *, enabled: bool) -> TerminalProgress | Silent:
    """A terminal display when ``enabled``, else :class:`Silent`."""
    return TerminalProgress(label) if enabled else Silent()
