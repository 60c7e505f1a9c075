"""Shared fixtures and independent geometry helpers for the tests."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from camtraj.robot import Robot
from camtraj.timing import Limits

_ROOT = Path(__file__).resolve().parents[1]

# One BLAS thread in every test process (numpy is loaded: threadpoolctl sets it) and in every
# command line the tests start (the environment, read when their numpy loads), as the shot
# solver and batch's workers already run. The suite keeps both cores busy (xdist workers, the
# shot set's pool, place -j 2), and an idle BLAS thread spinning for small matrices there costs
# more than it saves: three times the CPU on test_shot, test_convert and test_ik together.
# A variable set outside the suite is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
threadpool_limits(limits=int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")


@pytest.fixture(autouse=True)
def _root_logging_restored() -> Iterator[None]:
    """The root logger as it was before each test: a CLI run in-process (click's CliRunner)
    points it at a stderr that the runner closes, and a later test's logged USD warning
    then printed a "--- Logging error ---" trace."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    yield
    root.handlers[:] = handlers
    root.setLevel(level)


@pytest.fixture(scope="session")
def robot() -> Robot:
    return Robot.default()


def rot_z(a: float) -> NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def camera_path(robot: Robot, n: int = 240) -> NDArray[np.float64]:
    """A smooth previs-like camera move in the robot base frame, as flange poses (n, 4, 4).

    Track travel of 3 m with a sideways drift, a crane, a pan and a tilt, eased in and out,
    looking roughly down the track (the default mount's zero pose looks along +x).
    """
    s = np.linspace(0.0, 1.0, n)
    ease = 0.5 - 0.5 * np.cos(np.pi * s)
    x = 4.5 + 3.0 * ease
    y = 0.8 * np.sin(np.pi * s)
    z = 0.6 + 0.8 * ease
    yaw = 0.5 * np.sin(np.pi * s)
    pitch = -0.25 * ease
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    flange2camera = np.linalg.inv(robot.camera2flange)
    out = np.zeros((n, 4, 4))
    for i in range(n):
        cam = np.eye(4)
        cam[:3, :3] = rot_z(yaw[i]) @ rot_y(pitch[i]) @ look
        cam[:3, 3] = (x[i], y[i], z[i])
        out[i] = cam @ flange2camera
    return out


def pose_error(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[float, float]:
    """Largest position error [m] and rotation angle error [rad] between pose batches."""
    a = np.asarray(a).reshape(-1, 4, 4)
    b = np.asarray(b).reshape(-1, 4, 4)
    dp = float(np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1).max())
    rel = np.einsum("nji,njk->nik", a[:, :3, :3], b[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    # arccos loses precision near 0: use the skew part for small angles
    skew = np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                     rel[:, 1, 0] - rel[:, 0, 1]], axis=1)
    ang = np.arctan2(np.linalg.norm(skew, axis=1) / 2.0, cos)
    return dp, float(ang.max())


# The bad-input corpora (tests/test_hardening*.py) run many command lines. Each runs in a new
# process forked from a server that imported the pipeline once: the real command line
# (camtraj.__main__.run) with its own folder, stdout and stderr files, in its own process
# group (a batch's workers are killed with it), with an optional file size limit ("fsize",
# a disk that fills up) and alarm ("alarm" seconds: a run still going is killed by SIGALRM,
# exit code -14, a hang).
_FORK_SERVER = r"""
import json, os, resource, signal, sys, traceback
import camtraj.cli, camtraj.convert, camtraj.place, camtraj.farm, camtraj.report
from camtraj.__main__ import run

for line in sys.stdin:
    job = json.loads(line)
    sys.stdout.flush()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            os.setpgid(0, 0)
            os.chdir(job["cwd"])
            null = os.open(os.devnull, os.O_RDONLY)
            out = os.open(job["stdout"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            err = os.open(job["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(null, 0); os.dup2(out, 1); os.dup2(err, 2)
            if job.get("fsize"):
                resource.setrlimit(resource.RLIMIT_FSIZE, (job["fsize"], job["fsize"]))
            if job.get("alarm"):
                signal.signal(signal.SIGALRM, signal.SIG_DFL)
                signal.alarm(job["alarm"])
            sys.argv = ["camtraj", *job["args"]]
            run()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except BaseException:
            traceback.print_exc()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except BaseException:
                pass
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    try:
        os.killpg(pid, signal.SIGKILL)  # a batch's workers, if the run was killed
    except OSError:
        pass
    print(json.dumps({"id": job["id"], "rc": os.waitstatus_to_exitcode(status)}), flush=True)
"""


def run_forked(jobs: list[dict[str, object]], timeout: float) -> dict[str, int]:
    """Run every job's command line in a forked process (two servers, alternate jobs each);
    returns the exit code by job id (``-N``: killed by signal N).

    Each job: ``id``, ``cwd``, ``args`` (after ``camtraj``), ``stdout`` and ``stderr`` (file
    paths), optional ``fsize`` [bytes] and ``alarm`` [s].
    """
    def serve(part: list[dict[str, object]]) -> dict[str, int]:
        env = {**os.environ, "PYTHONPATH": str(_ROOT)}
        proc = subprocess.run(
            [sys.executable, "-c", _FORK_SERVER],
            input="".join(json.dumps(j) + "\n" for j in part),
            capture_output=True, text=True, env=env, timeout=timeout, check=False,
        )
        assert proc.returncode == 0, proc.stderr
        return {r["id"]: r["rc"] for r in map(json.loads, proc.stdout.splitlines())}

    codes: dict[str, int] = {}
    with ThreadPoolExecutor(2) as pool:
        for part in pool.map(serve, [jobs[0::2], jobs[1::2]]):
            codes.update(part)
    return codes


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every regular file under ``folder`` (symlinks not followed): relative path -> bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if not p.is_symlink() and p.is_file()}


@pytest.fixture(scope="session")
def limits(robot: Robot) -> Limits:
    """The default robot's limits as the timing stage reads them."""
    return Limits.from_robot(robot)
