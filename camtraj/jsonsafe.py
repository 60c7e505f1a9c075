"""JSON that every parser reads: no ``Infinity`` or ``NaN``, numpy values as plain numbers.

A number that is not finite becomes ``null``. Where camtraj writes such a value it documents
what null means; e.g. ``max_speed`` and ``feasible_fps`` are null for a still camera (the
pose never changes, so any speed is feasible: unbounded).
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["dumps", "finite"]


def finite(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (dicts, lists, tuples, numpy)."""
    if hasattr(obj, "tolist") and not isinstance(obj, str | bytes):
        obj = obj.tolist()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj


def dumps(obj: Any, *, indent: int | None = 2, sort_keys: bool = False) -> str:
    """``json.dumps`` of :func:`finite` ``(obj)``, strict (``allow_nan=False``)."""
    return json.dumps(finite(obj), indent=indent, sort_keys=sort_keys, allow_nan=False,
                      default=str)
