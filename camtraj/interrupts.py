"""Stopping a run on SIGINT (Ctrl-C) or SIGTERM (a render-farm scheduler cancelling a task).

:func:`install` (called first thing by the command line) makes both signals raise
:class:`Interrupted`, a ``KeyboardInterrupt``, so every ``finally`` and ``with`` on the way
out runs: temporary files are dropped and nothing is written. The command line turns it into
one ``ERROR:`` line and exit code 128 + the signal number (130 for SIGINT, 143 for SIGTERM).

Some code must not be interrupted half way, or swallows the exception: importing USD (its
C++ module loader catches Python errors raised while it runs, so a Ctrl-C there used to be
lost and the run went on to exit 0), removing temporary files, and committing the outputs.
Such code runs inside :func:`deferred`: a signal there is only recorded, and raised when the
block ends. :func:`check` raises a recorded stop (the outputs commit calls it first), so a
stop that some library swallowed still stops the run. Only the first signal raises; a second
Ctrl-C during the clean-up is recorded and does not interrupt it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

__all__ = ["Interrupted", "check", "deferred", "ignore_from_now", "install", "requested"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """The run was asked to stop by a signal.

    Attributes:
        signum: The signal number (``signal.SIGINT`` or ``signal.SIGTERM``).
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(self.signal_name)

    @property
    def signal_name(self) -> str:
        """``"SIGINT"`` or ``"SIGTERM"``."""
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        """The shell's convention: 128 + the signal number (130 for SIGINT)."""
        return 128 + self.signum


class _State:
    pending: int | None = None  # the first signal received
    raised = False  # an Interrupted was raised already
    depth = 0  # nesting of deferred()
    ignoring = False  # the result is committed: let the run complete


_state = _State()


def _handler(signum: int, frame: FrameType | None) -> None:
    if _state.pending is None:
        _state.pending = signum
    if _state.depth > 0 or _state.raised or _state.ignoring:
        return
    _state.raised = True
    raise Interrupted(signum)


def install() -> None:
    """Handle SIGINT and SIGTERM as described above (main thread only; else nothing)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in SIGNALS:
        signal.signal(signum, _handler)


def requested() -> int | None:
    """The signal number of a stop requested so far, else None."""
    return _state.pending


def check() -> None:
    """Raise :class:`Interrupted` if a stop was requested (even if it was swallowed)."""
    if _state.pending is not None and not _state.ignoring:
        _state.raised = True
        raise Interrupted(_state.pending)


@contextlib.contextmanager
def deferred(*, raise_pending: bool = True) -> Iterator[None]:
    """Record, rather than raise, a signal during the block; raise it when the block ends.

    Args:
        raise_pending: Raise a stop requested before or during the block when it ends
            (unless one was raised already). False for clean-up code.
    """
    _state.depth += 1
    try:
        yield
    finally:
        _state.depth -= 1
    if raise_pending and _state.depth == 0 and not _state.raised:
        check()


def ignore_from_now() -> None:
    """The run's result is committed: later signals no longer stop it."""
    _state.ignoring = True
