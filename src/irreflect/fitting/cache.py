"""Values the fitter computes once per model object, kept outside the (frozen) model.

Keyed by the model object's identity and dropped when the model is collected (a weak
reference), so a model rebuilt with other coefficients or starts never sees a stale
entry, and a frozen model is never written to.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Hashable

_CACHE: dict[int, tuple[weakref.ref, dict]] = {}


#: At most this many values per model (the oldest goes first): keys that carry a seed
#: would otherwise grow without bound in a long run.
MAX_VALUES = 256


def per_model(model, key: Hashable, make: Callable[[], object]):
    """The value ``make()`` computed once for ``model`` under ``key``."""
    entry = _CACHE.get(id(model))
    if entry is None or entry[0]() is not model:
        ident = id(model)
        entry = (weakref.ref(model, _forgetter(_CACHE, ident)), {})
        _CACHE[ident] = entry
    values = entry[1]
    if key not in values:
        if len(values) >= MAX_VALUES:
            values.pop(next(iter(values)))
        values[key] = make()
    return values[key]


def _forgetter(cache: dict, ident: int) -> Callable[[weakref.ref], None]:
    """The weakref callback that drops ``ident``'s entry from ``cache`` once its model is
    collected. It holds ``cache`` itself, not the module's global: a model collected at
    interpreter exit, after the module's globals are cleared, still finds it."""

    def forget(ref: weakref.ref) -> None:
        entry = cache.get(ident)
        if entry is not None and entry[0] is ref:
            del cache[ident]

    return forget
