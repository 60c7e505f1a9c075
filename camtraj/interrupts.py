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

Once the outputs are committed (:func:`ignore_from_now`) both signals are ignored by the
operating system, so one arriving while the process exits (when Python has put the default
handlers back) cannot kill a run whose result is on disk: it ends with its own exit code.

A stop raised where Python cannot pass it on (a weakref callback of the import system's
module locks, say) is "unraisable": Python would print it as a traceback and go on. The
stop is recorded all the same and :func:`check` raises it, so :func:`install` keeps such a
stop off stderr (every other unraisable exception is printed as before).

This module imports nothing but :mod:`signal` and :mod:`sys`: the command line installs it
before any other import, so that a signal in its first milliseconds is handled too.
"""

from __future__ import annotations

import signal
import sys

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from types import FrameType, TracebackType

__all__ = [
    "Interrupted",
    "check",
    "deferred",
    "ignore",
    "ignore_from_now",
    "install",
    "interruption",
]

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
    """Handle SIGINT and SIGTERM as described above, for a new run (main thread only).

    Forgets any earlier run's state: a ``batch`` worker calls it for each shot.
    """
    _state.pending, _state.raised, _state.depth, _state.ignoring = None, False, 0, False
    _set_handlers(_handler)
    if sys.unraisablehook is not _quiet_unraisable:
        _quiet_unraisable.default = sys.unraisablehook  # type: ignore[attr-defined]
        sys.unraisablehook = _quiet_unraisable


def _quiet_unraisable(unraisable: sys.UnraisableHookArgs, /) -> None:
    """Keep a stop Python could not raise off stderr (it is recorded: :func:`check` raises
    it); print anything else as Python would."""
    if isinstance(unraisable.exc_value, Interrupted):
        _state.raised = False  # not raised after all: the next check() raises it
        return
    _quiet_unraisable.default(unraisable)  # type: ignore[attr-defined]


def ignore() -> None:
    """Ignore SIGINT and SIGTERM (main thread only); a ``batch`` worker between shots."""
    _set_handlers(signal.SIG_IGN)


def _set_handlers(handler: signal.Handlers | Callable[[int, FrameType | None], None]) -> None:
    for signum in SIGNALS:
        for _attempt in range(3):
            try:
                signal.signal(signum, handler)
            except ValueError:  # not the main thread: signals are the main thread's business
                return
            except OSError:
                # A signal that arrived while its handler was being switched to SIG_IGN:
                # CPython reports it as "Signal N ignored due to race condition" instead of
                # changing the handler. It was ignored, as asked: set the handler again.
                continue
            break


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The stop behind an exception: ``exc`` itself, or the one it was raised from or while
    handling (Python wraps an exception raised in some places, e.g. a class attribute's
    ``__set_name__`` during an import, in a RuntimeError); None if there is none."""
    seen: set[int] = set()
    todo: list[BaseException | None] = [exc]
    while todo:
        e = todo.pop()
        if e is None or id(e) in seen:
            continue
        if isinstance(e, KeyboardInterrupt):
            return e
        seen.add(id(e))
        todo += [e.__cause__, e.__context__]
    return None


def check() -> None:
    """Raise :class:`Interrupted` if a stop was requested (even if it was swallowed)."""
    if _state.pending is not None and not _state.ignoring:
        _state.raised = True
        raise Interrupted(_state.pending)


class deferred:  # noqa: N801 - used as a function: ``with interrupts.deferred():``
    """Record, rather than raise, a signal during the block; raise it when the block ends.

    Args:
        raise_pending: Raise a stop requested before or during the block when it ends
            (unless one was raised already). False for clean-up code.
    """

    def __init__(self, *, raise_pending: bool = True) -> None:
        self.raise_pending = raise_pending

    def __enter__(self) -> None:
        _state.depth += 1

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        _state.depth -= 1
        if exc_type is None and self.raise_pending and _state.depth == 0 and not _state.raised:
            check()


def ignore_from_now() -> None:
    """The run's result is committed: later signals no longer stop it, nor kill it.

    (The operating system ignores them only where :func:`install` installed the handlers: a
    library caller keeps its own.)
    """
    _state.ignoring = True
    if signal.getsignal(signal.SIGINT) is _handler:
        ignore()
