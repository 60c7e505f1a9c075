"""How numbers are shown to a person, the same in the terminal and in the HTML report.

One rounding rule per kind of number, so the report and the terminal print the same text for
the same take: limit use rounds to the nearest percent; durations round half up to 10 ms after
removing float noise (0.0449999 s and 0.0450001 s are both 0.05 s); the maximum feasible
speed rounds down (a speed said to fit does fit).
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

__all__ = ["percent", "seconds", "speed_percent"]


def percent(x: float) -> str:
    """Use of a limit: '89%' (nearest), '>9999%' at 100x or more, '-' when not a number."""
    if not math.isfinite(x):
        return "-"
    return f"{100 * x:.0f}%" if x < 100.0 else ">9999%"


def seconds(x: float, digits: int = 2) -> str:
    """A duration or a take time [s] without its unit: '0.05'."""
    if not math.isfinite(x):
        return "-"
    exact = Decimal(f"{x:.6f}").quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP)
    return f"{exact:.{digits}f}"


def speed_percent(x: float) -> str:
    """The maximum feasible speed as % of real time, rounded down: '206%'."""
    return f"{math.floor(100.0 * x)}%"
