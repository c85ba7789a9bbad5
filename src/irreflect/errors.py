"""Exceptions raised by irreflect.

User errors (bad files, bad arguments, unknown names) derive from :class:`IrreflectError`,
a ``ValueError``: the CLI prints their message as one line and exits non-zero without a
traceback. A fit that cannot be completed raises :class:`FitError`.
"""

from __future__ import annotations

import difflib


class IrreflectError(ValueError):
    """A user error: the message says what was expected, what was found and how to fix it."""


class DataError(IrreflectError):
    """A measurement table that cannot be used as it is."""


class SchemaError(IrreflectError):
    """A document (scene, material file, checkpoint metadata, protocol) that does not follow
    its declared schema (:mod:`irreflect.schema`): one line naming the file, the key, what
    was expected, what was found and the fix."""


class SceneError(SchemaError):
    """A room scene that cannot be simulated: its file, a key, a material it names, or a
    rule that ties keys together (a receiver at an emitter, a box filling the room)."""


class UnknownNameError(IrreflectError):
    """A model, selector, extension or other registry name that does not exist."""


class FitError(RuntimeError):
    """A fit that did not reach a usable optimum; the message says why."""


class FitWarning(UserWarning):
    """A fit that is usable but not all it seems: not converged, a coefficient at a bound
    of its physical range, ill-determined coefficients, or an unphysical share. Every
    command prints these as one line each on stderr (``irreflect: warning: ...``)."""


class MetricWarning(RuntimeWarning):
    """A measure of fit that is undefined for its input (R^2 of a constant target): the
    value returned (-inf, NaN) is no score of the fit."""


def unknown_name(kind: str, name: str, valid) -> UnknownNameError:
    """Build the one-line error for a registry look-up that failed."""

    valid = sorted(valid)
    close = []
    if isinstance(name, str):  # matched regardless of case: 'TWO-LOBE' -> 'two-lobe'
        folded = {str(v).casefold(): str(v) for v in valid}
        close = [folded[m] for m in difflib.get_close_matches(name.casefold(), list(folded),
                                                                n=1)]
    hint = f" Did you mean '{close[0]}'?" if close else ""
    return UnknownNameError(
        f"unknown {kind} '{name}': expected one of {', '.join(valid)}.{hint}"
    )
