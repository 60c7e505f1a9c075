"""The HTML report's cost: what ``--report`` adds to ``camtraj convert`` of a one-minute shot,
and what ``camtraj report`` of a long take costs against ``camtraj info`` of the same file.

One ``convert(..., report=...)`` in a fresh process (so importing matplotlib is counted, as a
user pays it), split by stage: the ``report`` stage (import, figures, page) against the rest
of the same run. The 1-minute benchmark shot does not fit at its own timing, so it is timed
with ``--timing scale`` (as table 3 falls back to).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

_CHILD = """
import json, sys, time
from camtraj.convert import convert
from camtraj.options import ConvertOptions
shot, mcap, html = sys.argv[1:4]
assert "matplotlib" not in sys.modules
t0, c0 = time.perf_counter(), time.process_time()
summary = convert(shot, mcap, ConvertOptions(timing="scale"), report=html)
print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                  "stages_s": summary["timings"]}))
"""


def bench_report(shot: Path, work: Path) -> dict[str, Any]:
    """Convert ``shot`` once with a report; the report stage's share of the same run."""
    html = work / "report.html"
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, str(shot), str(work / "report.mcap"), str(html)],
        capture_output=True, text=True, check=False, timeout=3600,
    )
    if proc.returncode != 0:
        return {"skipped": f"convert --report failed: {proc.stderr.strip()[-300:]}"}
    res: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    report_s = float(res["stages_s"].get("report", 0.0))
    res["report_s"] = report_s
    res["ratio"] = report_s / (res["wall_s"] - report_s)
    res["html_bytes"] = html.stat().st_size
    return res


def print_report(res: dict[str, Any]) -> None:
    if "skipped" in res:
        print(f"\n5. The HTML report: skipped: {res['skipped']}")
        return
    print("\n5. The HTML report (convert --report of the 1-minute shot, timing=scale, one run)")
    print(f"   report stage {res['report_s']:.2f} s of {res['wall_s']:.2f} s wall: it adds "
          f"{100 * res['ratio']:.1f}% to the rest of the same run (goal: at most ~10%); "
          f"page {res['html_bytes'] / 1e6:.2f} MB (goal: under 1.5 MB)")


# ---------------------------------------------------------------------------------------------
# camtraj report of a long take, against camtraj info of the same file (issue 14, §5)
# ---------------------------------------------------------------------------------------------

_MEASURE = """
import resource, subprocess, sys, time
t0 = time.perf_counter()
proc = subprocess.run([sys.executable, "-m", "camtraj", *sys.argv[1:]], capture_output=True)
wall = time.perf_counter() - t0
assert proc.returncode == 0, proc.stderr.decode()[-300:]
print(wall, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""

FRAME_CAP = 100_000  # the most film frames a shot may have (camtraj.usd_shot)


def _measure(*args: str | Path) -> tuple[float, float]:
    """Wall time [s] and peak resident memory [KiB] of one ``camtraj ARGS`` process."""
    proc = subprocess.run([sys.executable, "-c", _MEASURE, *map(str, args)],
                          capture_output=True, text=True, check=True, timeout=3600)
    wall, kib = proc.stdout.split()
    return float(wall), float(kib)


def bench_report_file(work: Path, make_samples: Any, quick: bool) -> dict[str, Any]:
    """``camtraj report`` and ``camtraj info`` of two long takes (converted here, timing
    scale), each command in a new process, alternately, the median of a few runs: the
    report's time as a multiple of info's, and its peak memory per film frame (the slope
    between the two takes) extrapolated to the frame cap."""
    sizes = (1200, 4800) if quick else (4800, 24000)
    repeats = 1 if quick else 3
    out: dict[str, Any] = {"frames": list(sizes), "repeats": repeats}
    for n in sizes:
        shot, mcap = work / f"long{n}.usda", work / f"long{n}.mcap"
        make_samples.write_long_shot(shot, n_frames=n, fps=24.0)
        subprocess.run([sys.executable, "-m", "camtraj", "convert", str(shot), "-o",
                        str(mcap), "--timing", "scale", "-q"], check=True, timeout=3600,
                       capture_output=True)
        info, report = [], []
        for _ in range(repeats):
            info.append(_measure("info", mcap))
            report.append(_measure("report", mcap, "-o", work / f"long{n}.html"))
        res = {
            "mcap_mb": mcap.stat().st_size / 1e6,
            "info_s": statistics.median(w for w, _ in info),
            "report_s": statistics.median(w for w, _ in report),
            "info_peak_mib": max(k for _, k in info) / 1024,
            "report_peak_mib": max(k for _, k in report) / 1024,
        }
        res["report_over_info"] = res["report_s"] / res["info_s"]
        out[str(n)] = res
    small, big = (out[str(n)] for n in sizes)
    per_frame = (big["report_peak_mib"] - small["report_peak_mib"]) * 1024 / (sizes[1] -
                                                                            sizes[0])
    out["report_kib_per_frame"] = per_frame
    out["report_peak_at_cap_gib"] = (big["report_peak_mib"] + per_frame / 1024 * (
        FRAME_CAP - sizes[1])) / 1024
    return out


def print_report_file(res: dict[str, Any]) -> None:
    if "skipped" in res:
        print(f"\n5c. camtraj report of a long take: skipped: {res['skipped']}")
        return
    print(f"\n5c. camtraj report of long takes against camtraj info of the same files "
          f"(new processes, median of {res['repeats']})")
    print("   frames   MCAP MB   info s  report s  report/info  info MiB  report MiB")
    for n in res["frames"]:
        r = res[str(n)]
        print(f"   {n:>6} {r['mcap_mb']:9.1f} {r['info_s']:8.2f} {r['report_s']:9.2f} "
              f"{r['report_over_info']:11.2f}x {r['info_peak_mib']:9.0f} "
              f"{r['report_peak_mib']:11.0f}")
    print(f"   report peak memory per film frame {res['report_kib_per_frame']:.2f} KiB (the "
          f"slope between the two takes); extrapolated to the {FRAME_CAP:,}-frame cap "
          f"{res['report_peak_at_cap_gib']:.2f} GiB (goal: at most 1 GB)")
