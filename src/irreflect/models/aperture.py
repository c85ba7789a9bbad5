"""A model as a receiver of finite angular resolution measures it.

A real receiver does not read the power at one angle: it averages it over its acceptance,
``width`` degrees of receiver angle. :func:`with_aperture` gives the model whose curve is
that average (a box of ``width`` around each receiver angle, by Gauss-Legendre quadrature),
with the same coefficients: fitted to readings of such a receiver, they describe the
material (the lobe's peak and width as a point receiver would see them), not the blur.
The specular share depends on the angle of incidence only, so its saturation commutes with
the average. The compiled kernel does not implement the average: the numpy path fits it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..validation import check_number
from .base import ReflectionModel

#: Quadrature nodes across the receiver's acceptance (Gauss-Legendre: exact for
#: polynomials of degree 9; a 3-deg-wide lobe read by a 4-deg receiver is recovered to
#: 1e-5 of its index, tests/test_campaign.py).
APERTURE_NODES = 5


def check_resolution(width_deg) -> float:
    """A receiver's resolution (the full width, deg, of receiver angle a reading averages
    over), checked as every command and function that takes one checks it."""
    return check_number(width_deg, "the receiver's resolution (--resolution, deg)",
                        low=0.0, high=90.0)


def with_aperture(model: ReflectionModel, width_deg: float,
                  nodes: int = APERTURE_NODES) -> ReflectionModel:
    """``model`` as read by a receiver averaging over ``width_deg`` degrees (0: ``model``)."""
    width = check_resolution(width_deg)
    if not width > 0:
        return model
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    deltas = 0.5 * np.radians(width) * x
    weights = 0.5 * w
    base = model.basis

    def basis(geom, z, derivatives):
        total = dtotal = None
        for d, wt in zip(deltas, weights, strict=True):
            b, db = base(geom.shifted(d), z, derivatives)
            total = wt * b if total is None else total + wt * b
            if derivatives:
                dtotal = wt * db if dtotal is None else dtotal + wt * db
        return total, dtotal

    hints = dataclasses.replace(model.hints, kernel=None, batch_starts=None)
    return dataclasses.replace(
        model, basis=basis, hints=hints,
        formula=f"{model.formula}, averaged over a receiver {width:g} deg wide")


def unresolved(half_widths: dict[float, float], width_deg: float) -> str:
    """A warning when a fitted specular lobe is narrower than a receiver ``width_deg`` wide
    resolves: its full width at half maximum (twice ``half_widths[gamma]``, deg) below the
    width at some angles of incidence; empty otherwise (or with a point receiver)."""
    if not width_deg:
        return ""
    narrow = {g: h for g, h in half_widths.items() if np.isfinite(h) and 2.0 * h < width_deg}
    if not narrow:
        return ""
    where = ", ".join(f"{g:g}" for g in sorted(narrow, key=abs))
    width = min(2.0 * h for h in narrow.values())
    return (f"the fitted specular lobe is narrower than the receiver resolves at gamma "
            f"{where} deg (full width at half maximum down to {width:.2g} deg, against a "
            f"resolution of {width_deg:g} deg): the fit models each reading as the lobe "
            "averaged over the receiver's acceptance, so the lobe's peak and width rest on the "
            "model's lobe shape, not on readings that resolve it; measure it with a narrower "
            "aperture to check them")
