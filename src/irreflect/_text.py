"""Small helpers for the words of messages."""
from __future__ import annotations

import math


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and the noun, singular for one: ``count(1, "reading")`` is "1 reading",
    ``count(3, "reading")`` "3 readings"."""
    return f"{n} {noun if n == 1 else (plural or noun + 's')}"


def p_text(p: float) -> str:
    """``p = 0.012``, ``p = 3.1e-09`` or ``p < 1e-300`` (a p-value that underflows to 0,
    printed "p = 0" by a fit's chi^2 warning on tables with a sigma column)."""
    if not math.isfinite(p):
        return "p = n/a"
    if p <= 0.0:
        return "p < 1e-300"
    return f"p = {p:.3g}" if p >= 1e-4 else f"p = {p:.1e}"
