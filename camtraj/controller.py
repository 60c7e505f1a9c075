"""A motor controller's units: joint values (m, rad) to encoder counts, as a robot file's and a
lens file's ``[controller.AXIS]`` tables give them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["CONTROLLER_KEYS", "ControllerUnits", "controller_units"]


@dataclass(frozen=True)
class ControllerUnits:
    """Joint value to motor counts: ``counts = offset + sign * scale * q`` (q in m or rad)."""

    scale: float
    offset: float = 0.0
    sign: int = 1

    def counts(self, q: ArrayLike) -> NDArray[np.float64]:
        return self.offset + self.sign * self.scale * np.asarray(q, dtype=float)


CONTROLLER_KEYS = ("scale", "offset", "sign")
"""The keys of a ``[controller.AXIS]`` table (robot file and lens file alike)."""


def controller_units(table: dict[str, Any], key: str, number: Callable[[Any, str], float],
                     fail: Callable[[str, str], Exception],
                     per: str = "metre or radian") -> ControllerUnits:
    """A ``[controller.AXIS]`` table (``key``) as :class:`ControllerUnits`: ``scale``
    required and positive (counts per metre or radian; ``sign`` gives the direction),
    ``offset`` (default 0) and ``sign`` 1 or -1 (default 1). ``number`` reads a value as a
    finite number and ``fail`` makes the file's error, each naming the key; ``per``: the
    axis's unit, as the scale's error says it."""
    if "scale" not in table:
        raise fail(f"{key}.scale", "is missing")
    scale = number(table["scale"], f"{key}.scale")
    if not scale > 0.0:
        raise fail(f"{key}.scale", f"= {scale:g}: must be positive (counts per {per}; "
                   "sign gives the direction)")
    sign = table.get("sign", 1)
    if sign not in (1, -1) or isinstance(sign, bool):
        raise fail(f"{key}.sign", f"= {sign!r}: must be 1 or -1")
    return ControllerUnits(scale=scale, offset=number(table.get("offset", 0.0), f"{key}.offset"),
                           sign=int(sign))
