"""How numbers are shown to a person, the same in the terminal and in the HTML report.

One rounding rule per kind of number, so the report and the terminal print the same text for
the same take: limit use rounds to the nearest percent; durations round half up to 10 ms after
removing float noise (0.0449999 s and 0.0450001 s are both 0.05 s); the maximum feasible
speed rounds down (a speed said to fit does fit).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Iterable, Mapping, Sequence
from decimal import ROUND_HALF_UP, Decimal
from typing import Any

__all__ = ["EDGE_QUANTITIES", "MAX_SHOWN_SPEED", "SHOWN_RUNS", "SHOWN_TURN_DEG", "TIMES",
           "camera_moves", "distance", "edge_use", "frame_rate", "frame_runs", "frame_span",
           "listed", "percent", "scale_fit", "seconds", "servo", "speed_percent", "speed_text"]

TIMES = "\u00d7"
"""The multiplication sign (U+00D7): '1.3x its limit' in the report, with it for the x."""
#: What the "ends" columns show of the run-up and the run-out.
EDGE_QUANTITIES = ("acceleration", "jerk")


def percent(x: float) -> str:
    """Use of a limit: '89%' (nearest), '>9999%' at 100x or more, '-' when not a number."""
    if not math.isfinite(x):
        return "-"
    return f"{100 * x:.0f}%" if x < 100.0 else ">9999%"


def frame_span(first: object, last: object, text: Callable[[Any], str] = str) -> str:
    """Film frames first to last: '1001-1096', or '-24 to 23' when a frame is negative (a
    hyphen would read as a minus sign: '-30--1'); each frame written by ``text``."""
    negative = any(isinstance(f, numbers.Real) and f < 0 for f in (first, last))
    a, b = text(first), text(last)
    return f"{a} to {b}" if negative else f"{a}-{b}"


#: An error line shows more runs of frames than this as the first and last few and their
#: count (a handheld shake over its jerk limits listed 35 runs per axis, over 1,000
#: characters on one line; check --json and the report keep every frame).
SHOWN_RUNS = 8


def frame_runs(runs: Iterable[tuple[int, int]], most: int | None = None) -> str:
    """Runs of film frames (first, last): 'frames 12-19, 40' ('frames -3 to -1, 4'); one
    frame alone: 'frame 40'; more than ``most`` runs (every run where None): the first five,
    '...', the last two and the count ('frames 0-10, 12-16, 34-37, 39-50, 52-55, ...,
    289-292, 295-299 (30 stretches)')."""
    runs = list(runs)
    if len(runs) == 1 and runs[0][0] == runs[0][1]:
        return f"frame {runs[0][0]}"
    shown = [frame_span(a, b) if b != a else f"{a}" for a, b in runs]
    if most is not None and len(shown) > most:  # most >= 7: what the short form shows
        return (f"frames {', '.join(shown[:5])}, ..., {', '.join(shown[-2:])} "
                f"({len(shown)} stretches)")
    return "frames " + ", ".join(shown)


def listed(words: Sequence[str]) -> str:
    """Words as a person lists them: 'a', 'a and b', 'a, b and c'."""
    return " and ".join(words) if len(words) <= 2 else f"{', '.join(words[:-1])} and {words[-1]}"


def seconds(x: float, digits: int = 2) -> str:
    """A duration or a take time [s] without its unit: '0.05'."""
    if not math.isfinite(x):
        return "-"
    exact = Decimal(f"{x:.6f}").quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP)
    return f"{exact:.{digits}f}"


def distance(metres: float) -> str:
    """A distance a crew reads at a glance: millimetres below 1 cm, centimetres to 1 m."""
    if metres < 0.01:
        return f"{metres * 1e3:.1f} mm"
    return f"{metres * 100:.1f} cm" if metres < 1.0 else f"{metres:.2f} m"


#: [deg] The smallest turn of the camera in a run-up or run-out that is said (a pan alone
#: moves the camera little, so its travel alone can look like nothing).
SHOWN_TURN_DEG = 0.1


def camera_moves(runup: tuple[float, float], runout: tuple[float, float]) -> str:
    """How far the run-up and run-out move the camera from the first and last frame's pose,
    each (metres, degrees): 'the camera moves 4.2 cm and turns 3.3 deg before the first frame,
    0.0 mm after the last' (a turn from :data:`SHOWN_TURN_DEG`)."""

    def part(metres: float, deg: float) -> str:
        return distance(metres) + (f" and turns {deg:.1f} deg" if deg >= SHOWN_TURN_DEG else "")

    return (f"the camera moves {part(*runup)} before the first frame, {part(*runout)} after "
            "the last")


def servo(rate_hz: float, step_ms: tuple[float, float] | None) -> str:
    """The take's servo grid: 'servo 250.0 Hz', or where an optimal retime's steps differ,
    their range (each frame interval is cut into equal steps: not a fixed period).
    ``step_ms``: the shortest and longest step [ms], None when not known (the rate alone)."""
    if step_ms is not None:
        short, long = step_ms
        # steps a nanosecond apart are one period on the file's clock (whole nanoseconds)
        if long - short > max(1e-6 * long, 1.5e-6):
            return (f"servo steps {short:.3f}-{long:.3f} ms (each frame interval in equal "
                    "steps, every frame a sample: not a fixed period)")
        if long > 0.0:
            rate_hz = 1e3 / long
    return f"servo {rate_hz:.1f} Hz"


MAX_SHOWN_SPEED = 100.0
"""Above this many times real time a maximum feasible speed shows as '>10000%' (the number
means nothing on set), in the terminal, the report, batch's and place's tables alike."""


def speed_percent(x: float) -> str:
    """The maximum feasible speed as % of real time, rounded down: '206%'; below 1%, to two
    significant digits ('0.29%', not '0%'); above :data:`MAX_SHOWN_SPEED`, '>10000%'."""
    if x > MAX_SHOWN_SPEED:
        return f">{100 * MAX_SHOWN_SPEED:.0f}%"
    p = 100.0 * x
    if p >= 1.0 or p <= 0.0:
        return f"{math.floor(p)}%"
    decimals = 1 - math.floor(math.log10(p))
    shown = math.floor(p * 10 ** decimals * (1.0 + 1e-12)) / 10 ** decimals  # 0.29, not 0.28999
    return f"{shown:.{decimals}f}%"


def frame_rate(fps: float, digits: int = 2) -> str:
    """A frame rate a take fits at, rounded down (a rate said to fit does fit): '19.06'."""
    scale = 10.0**digits
    return f"{math.floor(fps * scale * (1.0 + 1e-12)) / scale:.{digits}f}"


def speed_text(max_speed: float | None, fps: float, feasible_fps: float | None = None) -> str:
    """'131% of real time (could be shot at 31.54 fps)' for a take of ``fps`` frames per
    second (``feasible_fps``: the rate the file records, where it does); a still camera's
    speed (None or infinite) is unbounded; above :data:`MAX_SHOWN_SPEED`, a bound."""
    if max_speed is None or not math.isfinite(max_speed):
        return "unbounded (the camera pose never changes)"
    if max_speed > MAX_SHOWN_SPEED:
        return (f"{speed_percent(max_speed)} of real time (could be shot at more than "
                f"{frame_rate(MAX_SHOWN_SPEED * fps, 0)} fps)")
    shown = feasible_fps if feasible_fps is not None else max_speed * fps
    return f"{speed_percent(max_speed)} of real time (could be shot at {frame_rate(shown)} fps)"


def edge_use(runup: Mapping[str, Mapping[str, float]], runout: Mapping[str, Mapping[str, float]],
             names: Iterable[str]) -> dict[str, dict[str, float]]:
    """Per axis, the run-up's and the run-out's peak acceleration and jerk use (the larger of
    the two), apart from the shot's: the "ends" columns of the terminal and the report.

    ``runup`` and ``runout`` map axis -> quantity -> fraction of the limit (a missing one: 0).
    """
    out = {}
    for name in names:
        parts = [side.get(name, {}) for side in (runup, runout)]
        out[name] = {q: max((float(p.get(q, 0.0)) for p in parts), default=0.0)
                     for q in EDGE_QUANTITIES}
    return out


def scale_fit(factor: float, fps: float) -> str:
    """'fits at 58% speed (14.70 fps)': the speed of the scale take, the shot slowed by
    ``factor`` (a hair slower than the maximum feasible speed where the servo grid rounds it)."""
    return f"fits at {speed_percent(1.0 / factor)} speed ({frame_rate(fps / factor)} fps)"
