"""JSON for every file and ``--json`` output irreflect writes: one encoder, one sanitiser.

JSON has no NaN, no infinity and no numpy types. :func:`json_default` turns numpy scalars
and arrays into Python values (for ``json.dump(default=...)``); :func:`finite` makes a
JSON-safe copy of a nested structure with NaN and infinities as ``null``; :func:`dumps`
does both, so that what irreflect writes is strict JSON any reader accepts.
"""

from __future__ import annotations

import json
import math
from pathlib import PurePath

import numpy as np


def json_default(o):
    """``json.dump(default=...)``: numpy scalars and arrays, paths."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, PurePath):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def finite(obj):
    """JSON-safe copy: numpy scalars and arrays to Python, NaN and infinities to ``None``,
    dictionary keys to strings, tuples to lists."""
    if isinstance(obj, dict):
        return {str(k): finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps(obj, indent: int | None = 2) -> str:
    """Strict JSON text of ``obj`` (see :func:`finite`), ending in a newline."""
    return json.dumps(finite(obj), indent=indent, default=json_default, allow_nan=False) + "\n"
