"""``python -m camtraj`` and the ``camtraj`` command: the command line.

Signals are handled before anything heavy is imported (:mod:`camtraj.interrupts`), so a
Ctrl-C or a SIGTERM at any moment gives one line and exit 130 / 143, never a traceback.
"""

from __future__ import annotations

from camtraj import interrupts


def run() -> None:
    """Entry point of the ``camtraj`` command."""
    interrupts.install()
    try:
        from camtraj.cli import main
    except KeyboardInterrupt as exc:
        _stopped_while_starting(exc)
    main()


def _stopped_while_starting(exc: KeyboardInterrupt) -> None:
    import sys

    signum = getattr(exc, "signum", 2)
    name = {2: "SIGINT", 15: "SIGTERM"}.get(signum, f"signal {signum}")
    sys.stderr.write(f"ERROR: stopped by {name}; nothing was written\n")
    raise SystemExit(128 + signum)


if __name__ == "__main__":
    run()
