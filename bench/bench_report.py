"""The HTML report's cost: what ``--report`` adds to ``camtraj convert`` of a one-minute shot.

One ``convert(..., report=...)`` in a fresh process (so importing matplotlib is counted, as a
user pays it), split by stage: the ``report`` stage (import, figures, page) against the rest
of the same run. The 1-minute benchmark shot does not fit at its own timing, so it is timed
with ``--timing scale`` (as table 3 falls back to).
"""

from __future__ import annotations

import json
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
