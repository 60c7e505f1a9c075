"""The HTML report a crew looks at before the shoot day (``camtraj report``, ``--report``).

One plain data object, :class:`ReportData`, is built from either source and rendered by one
function, :func:`render_html`:

- :func:`from_analysis`: the in-memory run of ``convert --report`` / ``check --report``,
  a shot that fails included;
- :func:`from_take` / :func:`report_from_mcap`: a camtraj MCAP read back.

``data`` holds the data and its builders, ``samples`` folds the servo samples into what the
page shows (bounded by the frames and the plot width), ``page`` the HTML, ``plots`` the
matplotlib figures (matplotlib is imported only when a figure is drawn).
"""

from camtraj.report.data import (
    ReportData,
    Violation,
    from_analysis,
    from_take,
    pose_indices,
    report_from_mcap,
)
from camtraj.report.page import render_html, report_mcap
from camtraj.report.samples import Samples, reduce_samples
from camtraj.timing.limits import QUANTITIES

__all__ = [
    "QUANTITIES",
    "ReportData",
    "Samples",
    "Violation",
    "from_analysis",
    "from_take",
    "pose_indices",
    "reduce_samples",
    "render_html",
    "report_from_mcap",
    "report_mcap",
]
