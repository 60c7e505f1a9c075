"""``python -m camtraj`` and the ``camtraj`` command: the command line.

Signals are handled from the import of this module on, before anything else is imported
(the :mod:`camtraj` package and :mod:`camtraj.interrupts` import only :mod:`signal`): a
Ctrl-C or a SIGTERM at any moment of camtraj's own code gives one line and exit 130 / 143,
never a traceback. (While Python itself starts, about 10-30 ms before that, Python's
defaults apply: SIGINT prints Python's traceback, SIGTERM ends the process silently.)

When this module is the program (the ``camtraj`` console script, ``python -m camtraj``) it
installs the handlers as it is imported, holding a signal until :func:`run` raises it, where
it becomes the one line; imported by anything else, it installs nothing until :func:`run`.
"""

from __future__ import annotations

import sys

from camtraj import interrupts

_starting: interrupts.deferred | None = None
if __name__ == "__main__" or sys.argv[0].replace("\\", "/").rsplit("/", 1)[-1].startswith(
    "camtraj"
):
    interrupts.install()
    _starting = interrupts.deferred()
    _starting.__enter__()  # a signal from now until run() is held, and raised inside it


def run() -> None:
    """Entry point of the ``camtraj`` command."""
    global _starting
    try:
        if _starting is None:
            interrupts.install()
        else:
            held, _starting = _starting, None
            held.__exit__(None, None, None)  # raises a signal held since the import
        from camtraj.cli import main
    except BaseException as exc:  # a stop may come wrapped in another error
        stop = interrupts.interruption(exc)
        if stop is None:
            raise
        _stopped_while_starting(stop)
    main()


def _stopped_while_starting(exc: KeyboardInterrupt) -> None:
    interrupts.ignore()  # the exit below is not interrupted by a second signal
    signum = getattr(exc, "signum", 2)
    name = {2: "SIGINT", 15: "SIGTERM"}.get(signum, f"signal {signum}")
    sys.stderr.write(f"ERROR: stopped by {name}; nothing was written\n")
    raise SystemExit(128 + signum)


if __name__ == "__main__":
    run()
