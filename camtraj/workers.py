"""Worker processes for batch and place: how many, how they start, and their environment."""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.context
import os
import signal
import threading
from collections.abc import Iterator

from camtraj.errors import InputError

__all__ = ["WORKER_ENV", "default_jobs", "mp_context", "start_workers_early",
           "worker_environment"]


def default_jobs(jobs: int | None) -> int:
    """Worker processes: the CPUs this process may use unless given.

    Raises:
        InputError: Fewer than one.
    """
    if jobs is None:
        jobs = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
            os.cpu_count() or 1)
    if jobs < 1:
        msg = f"jobs must be at least 1, got {jobs}"
        raise InputError(msg)
    return jobs


WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "PYTHONSAFEPATH": "1"}
"""Worker environment: one BLAS thread per worker, as the workers already use every core;
and no current folder on the fork server's import path (it starts as ``python -c``, which
puts it first: a folder named ``camtraj`` there, a clone of this repository say, was
imported instead of the installed package and every worker failed)."""


@contextlib.contextmanager
def worker_environment() -> Iterator[None]:
    """Set :data:`WORKER_ENV` (where the user has not) while worker processes are started,
    and start them with SIGINT ignored: Ctrl-C signals the whole process group, and the fork
    server, importing the pipeline in its first second, printed a KeyboardInterrupt
    traceback under the command's one line (trial 22). The command stops its workers
    itself; a shot handles the signals while it runs (:func:`camtraj.interrupts.install`)."""
    added = [k for k in WORKER_ENV if k not in os.environ]
    os.environ.update({k: WORKER_ENV[k] for k in added})
    main = threading.current_thread() is threading.main_thread()
    before = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        yield
    finally:
        if main:
            signal.signal(signal.SIGINT, before)
        for k in added:
            os.environ.pop(k, None)


def mp_context() -> multiprocessing.context.BaseContext:
    """How workers start: forked from a clean server that has imported the pipeline (fast and
    thread-safe); spawned where there is no fork server (Windows)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["camtraj.convert"])
        return ctx
    return multiprocessing.get_context("spawn")


def start_workers_early() -> None:
    """Start the worker fork server now, so that it imports the pipeline while this process does.

    Optional: :func:`camtraj.batch.run_batch` starts it anyway. Calling this before the first
    import of :mod:`camtraj.convert` overlaps the two imports (about a second each) on two
    cores.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return
    from multiprocessing import forkserver

    mp_context()
    with worker_environment():
        forkserver.ensure_running()
