"""Small helpers for the words of messages."""
from __future__ import annotations


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and the noun, singular for one: ``count(1, "reading")`` is "1 reading",
    ``count(3, "reading")`` "3 readings"."""
    return f"{n} {noun if n == 1 else (plural or noun + 's')}"
