"""What a table's curve looks like when a model cannot beat a constant on it.

The refusal used to blame the angle convention or the power whatever the table showed; a
velvet-like table of the held-out generator ``experiments/unseen_tables3.py`` (its power
rises toward grazing receivers at every angle of incidence, the convention kept) was told
to check its angles. :func:`peak_hint` says where the readings peak instead, and
:func:`explained` puts that into the error.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import FitError

#: The generic advice of a fit that cannot beat a constant
#: (:func:`irreflect.fitting.finish._check_r2` writes this constant), replaced when the
#: table's peaks say more.
GENERIC_ADVICE = ("check that power is the reflected power and that the angles follow the "
                  "convention (gamma < 0 on the source side, mirror at theta = -gamma)")

_NEAR_DEG = 8.0  # a peak this close to the mirror or the source direction is "at" it
_GRAZING_DEG = 70.0  # a peak at |theta| this large, away from both, is "at grazing"


def _peaks(meas) -> list[tuple[float, float]]:
    """(gamma, theta of the largest reading) per angle of incidence with >= 3 readings."""
    gamma = np.asarray(meas.gamma_deg, float)
    theta = np.asarray(meas.theta_deg, float)
    power = np.asarray(meas.power, float)
    out = []
    for g in np.unique(gamma):
        at = gamma == g
        if np.count_nonzero(at) >= 3:
            out.append((float(g), float(theta[at][np.argmax(power[at])])))
    return out


def _kind(gamma: float, theta: float) -> str:
    if abs(theta + gamma) <= _NEAR_DEG:
        return "mirror"
    if abs(gamma) > _NEAR_DEG and abs(theta - gamma) <= _NEAR_DEG:
        return "source"
    return "grazing" if abs(theta) >= _GRAZING_DEG else "elsewhere"


def peak_hint(meas, model: str = "two-lobe") -> str | None:
    """Where the table's readings peak, and what that says of a fit of ``model`` (its
    registry name), when most angles of incidence agree; None when they do not (the
    generic advice stands)."""
    found = peak_summary(meas, model)
    return None if found is None else found[1]


def peak_summary(meas, model: str = "two-lobe") -> tuple[str, str] | None:
    """``(kind, hint)``: where most angles of incidence peak (``"mirror"``, ``"source"``
    or ``"grazing"``) and what that says of a fit of ``model``; None when they do not
    agree."""
    peaks = _peaks(meas)
    if not peaks:
        return None
    kinds = [_kind(g, t) for g, t in peaks]
    top = max(set(kinds), key=kinds.count)
    n, m = kinds.count(top), len(kinds)
    if 2 * n <= m or top == "elsewhere":
        return None
    thetas = [t for (_, t), k in zip(peaks, kinds, strict=True) if k == top]
    at = f"theta {min(thetas):g}..{max(thetas):g} deg" if len(set(thetas)) > 1 \
        else f"theta {thetas[0]:g} deg"
    where = f"at {n} of {m} angles of incidence ({at})"
    if top == "mirror":
        return top, (f"its readings peak at the mirror direction theta = -gamma {where}, so the "
                "angles follow the convention: the power is dominated by what the model "
                "has no term for (an offset, stray light: try the model with '+background', "
                f"e.g. --model {model}+background; or a lobe it lacks: 'irreflect compare' "
                "tries the other models)")
    if top == "source":
        return top, (f"its readings peak at the source direction theta = gamma {where}, not at "
                "the mirror theta = -gamma: if theta was counted positive on the source "
                "side, change its sign; a retroreflector peaks there and the model has no "
                "such lobe (try the model with '+retroreflection')")
    return top, (f"its readings peak at grazing receivers (|theta| >= {_GRAZING_DEG:g} deg) "
            f"{where}, away from both the mirror theta = -gamma and the source direction: "
            "a material that brightens toward grazing (velvet, cloth, a sheen) has no lobe "
            "in this model, whose lobes peak at the mirror direction and the normal; check "
            "that power is the reflected power in the paper's angles, or describe the "
            "material another way")


def explained(exc: FitError, meas) -> FitError:
    """``exc`` with the generic advice replaced by :func:`peak_hint`, when it says more."""
    text = str(exc)
    if GENERIC_ADVICE not in text:
        return exc
    named = re.match(r"fit of '([^'+@]+)", text)  # the model, without its extensions
    hint = peak_hint(meas, named.group(1) if named else "two-lobe")
    return exc if hint is None else FitError(text.replace(GENERIC_ADVICE, hint))
