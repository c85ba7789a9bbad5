"""A fit's verdict: what R^2 cannot say about a fitted shape.

R^2 weighs every point alike, so a glossy material's fit can reach 0.99 while its specular
lobe is seen by one receiver (its width, which decides how a room spreads the reflected
power, is then not measured at all) and its curve between the receivers is a guess. The
verdict looks at each angle of incidence:

* **the specular lobe**: its half width at half maximum (from the fitted index ``n_s``:
  ``acos(2^(-1/n_s))``), how many measured receivers lie within one and within two half
  widths of the mirror direction, and whether the lobe matters there (its peak at least
  :data:`SIGNIFICANT` of the diffuse level in the mirror direction). A lobe that matters
  is *resolved* when at least two receivers lie within two half widths of the mirror
  (where the lobe is above 1/16 of its peak), one of them within one half width;
* **the polar-area error** (section 5.3), twice: of the model at the measured receivers
  (the misfit where it was measured, noise included) and of the model's continuous curve
  (a spike the model draws between two receivers counts: the room integrates that curve,
  not its values at the receivers). The shape is not reproduced where the first exceeds
  :data:`POLAR_ERROR_LIMIT` percent, or the second exceeds the first by more than
  :data:`UNMEASURED_LIMIT` points (the curve has structure no receiver saw). When that
  excess lies where the specular lobe is (between the receivers bracketing two half widths
  of the mirror) and the receivers there stand more than half a half width apart, the
  comparison with the measured points joined by straight lines cannot judge the lobe's
  shape: the lobe is *under-sampled* there (a receiver step of half its half width lets
  straight segments miss under 5 % of its polar area; one of a whole half width, 15 %), and
  the verdict says so instead of "shape not reproduced" (a table of the model's own law
  with receivers 5 deg apart and a lobe 3.5 deg wide was said not to reproduce its shape,
  20-50 % of the whole curve, with its coefficients recovered within 4 %);
* **the coefficients**: at a bound of their physical range, ill-determined, or a search
  that did not converge (the fit's own checks);
* **a fit at one angle of incidence** (``MODEL@G``, the paper's Phong at 10 deg): it is
  judged at that angle only and says so, and it is not trustworthy when it explains all
  the table's points below :data:`irreflect.metrics.MISFIT_R2` (Phong at 10 deg on
  terrazzo: 6.2 % at 10 deg, R^2 0.224 on all 132 points).

* **clipped readings**: three or more readings (at most half the table) equal to the
  largest power exactly look like a saturated detector (:func:`irreflect.data.
  saturated_readings`); the fit is of the clipped curve, its lobe wider and lower than the
  material's (a held-out Ward table with 92 of 453 readings at the maximum was called
  trustworthy).

A fit is *trustworthy* when none of these is flagged. The summary line leads every fit
report and is written into material files (``irreflect fit --save``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import metrics
from .models.paper import specular_share

#: The specular lobe matters at an angle of incidence when its peak is at least this
#: fraction of the diffuse lobe's level in the mirror direction.
SIGNIFICANT = 0.1
#: Polar-area error at the measured receivers (percent) above which a fit does not
#: reproduce an angle's shape: the paper's own fits stay within 6 %, its Phong comparison
#: reaches 15-68 %, the noisy reconstructions of its materials 8-14 %.
POLAR_ERROR_LIMIT = 25.0
#: Percentage points by which the continuous curve's polar-area error may exceed the
#: error at the receivers before the curve is said to have structure nobody measured.
UNMEASURED_LIMIT = 10.0


@dataclass(frozen=True)
class AngleVerdict:
    """One angle of incidence of a fit's verdict (angles in degrees, errors in percent)."""

    gamma_deg: float  # |gamma|
    n_points: int
    polar_error_pct: float  # of the model's continuous curve
    polar_error_at_points_pct: float  # of the model at the measured receivers
    specular_share: float  # the fitted a_s there (NaN for a model without one)
    lobe_half_width_deg: float  # half width at half maximum of the specular lobe (NaN: none)
    lobe_points_1hw: int  # receivers within one half width of the mirror direction
    lobe_points_2hw: int  # ... within two half widths
    lobe_matters: bool
    #: the curve's excess over the error at the receivers lies in the lobe's window, where
    #: the receivers stand too far apart for straight segments to follow the lobe
    lobe_undersampled: bool = False
    #: the widest gap between receivers across the lobe's window (deg; NaN: not looked at)
    lobe_receiver_gap_deg: float = float("nan")
    #: why the angle has no polar area ("" where it has one): "points" (fewer than two),
    #: "zero" (every reading zero: no measured area to compare with), "span" (the readings
    #: stand at one receiver angle)
    no_area: str = ""

    @property
    def lobe_resolved(self) -> bool:
        return (not self.lobe_matters) or (self.lobe_points_2hw >= 2
                                           and self.lobe_points_1hw >= 1)

    @property
    def shape_reproduced(self) -> bool:
        unmeasured = (self.polar_error_pct - self.polar_error_at_points_pct
                      > UNMEASURED_LIMIT)
        return not (self.polar_error_at_points_pct > POLAR_ERROR_LIMIT
                    or (unmeasured and not self.lobe_undersampled))

    @property
    def step_needed_deg(self) -> float:
        """The receiver step near the mirror that lets the polar-area comparison follow the
        lobe (half its half width, rounded down to two digits; NaN without a lobe)."""
        return _floor2(self.lobe_half_width_deg / 2.0)

    @property
    def ok(self) -> bool:
        return self.lobe_resolved and self.shape_reproduced and not self.lobe_undersampled

    def to_dict(self) -> dict:
        return {"gamma_deg": self.gamma_deg, "n_points": self.n_points,
                "polar_error_pct": _num(self.polar_error_pct),
                "polar_error_at_points_pct": _num(self.polar_error_at_points_pct),
                "specular_share": _num(self.specular_share),
                "lobe_half_width_deg": _num(self.lobe_half_width_deg),
                "lobe_points_1hw": self.lobe_points_1hw,
                "lobe_points_2hw": self.lobe_points_2hw, "lobe_matters": self.lobe_matters,
                "lobe_resolved": self.lobe_resolved,
                "lobe_undersampled": self.lobe_undersampled, "ok": self.ok}


@dataclass(frozen=True)
class FitVerdict:
    """A fit's verdict (see the module docstring)."""

    angles: tuple[AngleVerdict, ...]
    at_bound: tuple[str, ...]
    ill_determined: tuple[str, ...]
    converged: bool
    saturated_gammas_deg: tuple[float, ...]
    #: a ``MODEL@G`` fit: the |gamma| it was fitted to and judged at, and its score on all
    #: the table's points (``{"n_points", "r2", "rmse"}``); None for a fit of all points
    fitted_at_deg: float | None = None
    on_all_points: dict | None = None
    #: readings that look clipped by a saturated detector: (how many, of how many, the
    #: power they share); () when none (:func:`irreflect.data.saturated_readings`)
    clipped: tuple = ()

    @property
    def misses_other_angles(self) -> bool:
        """A fit at one angle of incidence that explains the whole table below
        :data:`irreflect.metrics.MISFIT_R2`."""
        if not self.on_all_points:
            return False
        return not self.on_all_points["r2"] >= metrics.MISFIT_R2

    @property
    def unresolved(self) -> tuple[AngleVerdict, ...]:
        return tuple(a for a in self.angles if not a.lobe_resolved)

    @property
    def misshapen(self) -> tuple[AngleVerdict, ...]:
        return tuple(a for a in self.angles if not a.shape_reproduced)

    @property
    def undersampled(self) -> tuple[AngleVerdict, ...]:
        """Angles whose lobe has its points but too few for the polar-area comparison (an
        unresolved lobe is named as such)."""
        return tuple(a for a in self.angles if a.lobe_undersampled and a.lobe_resolved)

    @property
    def trustworthy(self) -> bool:
        return (self.converged and not self.at_bound and not self.ill_determined
                and not self.unresolved and not self.misshapen and not self.undersampled
                and not self.misses_other_angles and not self.clipped)

    def problems(self) -> list[str]:
        """One phrase per kind of problem (empty when trustworthy)."""
        out = []
        if self.clipped:  # first: every other finding is of the clipped curve
            count, total, top = self.clipped
            out.append(f"a saturated detector? {count} of {total} readings equal the largest "
                       f"power, {top:g}, exactly: clipped readings flatten the lobe's top, so "
                       "the fitted lobe is wider and lower than the material's (measure them "
                       "again with less gain, or leave them out)")
        if self.misses_other_angles:
            out.append(f"fitted at |gamma| = {self.fitted_at_deg:g} deg only, it explains all "
                       f"{self.on_all_points['n_points']} points to R^2 "
                       f"{self.on_all_points['r2']:.3g} (below {metrics.MISFIT_R2:g}): it "
                       "misses the other angles of incidence")
        if self.unresolved:
            parts = [f"{a.gamma_deg:g} deg ({a.lobe_points_1hw} point(s) within its half width "
                     f"of {a.lobe_half_width_deg:.2g} deg)" for a in self.unresolved]
            out.append(_listed("specular lobe not resolved", parts, self.unresolved,
                               [a.lobe_half_width_deg for a in self.unresolved])
                       + ": its width is not measured")
        if self.undersampled:
            out.append(_undersampled_text(self.undersampled))
        if self.misshapen:
            parts = [f"{a.gamma_deg:g} deg (polar-area error "
                     f"{_pct(a.polar_error_at_points_pct)} % at the receivers, "
                     f"{_pct(a.polar_error_pct)} % of the whole curve)" for a in self.misshapen]
            out.append(_listed("shape not reproduced", parts, self.misshapen,
                               [-_worst_error(a) for a in self.misshapen]))
        if self.at_bound:
            out.append("at a bound: " + ", ".join(self.at_bound))
        if self.ill_determined:
            out.append("ill-determined: " + ", ".join(self.ill_determined))
        if not self.converged:
            out.append("the search did not converge")
        return out

    def summary(self) -> str:
        """One line that leads the fit's report."""
        if self.trustworthy:
            worst = max((a.polar_error_pct for a in self.angles
                         if np.isfinite(a.polar_error_pct)), default=float("nan"))
            lobes = [a for a in self.angles if a.lobe_matters]
            at = "every angle" if self.fitted_at_deg is None else "that angle"
            text = ("verdict: trustworthy" + self._where() + ": every coefficient determined, "
                    f"polar-area error of the whole curve <= {_pct(worst)} % at {at} of "
                    "incidence")
            if lobes:
                text += (", the specular lobe resolved wherever it matters (>= "
                         f"{min(a.lobe_points_2hw for a in lobes)} points within two half "
                         "widths)")
        else:
            text = "verdict: NOT TRUSTWORTHY (whatever R^2 says): " + "; ".join(self.problems())
        if self.saturated_gammas_deg:
            text += ("; the specular share is 1 (all specular) at |gamma| = "
                     + ", ".join(f"{g:g}" for g in self.saturated_gammas_deg) + " deg")
        return text

    def _where(self) -> str:
        """What a fit at one angle of incidence was judged on ("" for a fit of all points)."""
        if self.fitted_at_deg is None:
            return ""
        text = f" at |gamma| = {self.fitted_at_deg:g} deg only"
        if self.on_all_points:
            text += (f" (R^2 {self.on_all_points['r2']:.3g} on all "
                     f"{self.on_all_points['n_points']} points)")
        return text

    def table(self) -> list[str]:
        """Per angle of incidence: points, polar-area error, share, lobe width and points."""
        rows = [f"{'|gamma|':>8}{'points':>8}{'err % pts':>11}{'err % curve':>13}{'a_s':>8}"
                f"{'lobe HWHM':>11}{'in 1 HW':>9}{'in 2 HW':>9}  verdict"]
        for a in self.angles:
            word = "ok" if a.ok else ("lobe unresolved" if not a.lobe_resolved
                                      else "shape not reproduced" if not a.shape_reproduced
                                      else "lobe under-sampled")
            if a.lobe_resolved and not a.lobe_matters:
                word += " (no lobe that matters)" if a.ok else ""
            rows.append(f"{a.gamma_deg:>8g}{a.n_points:>8d}"
                        f"{_pct_cell(a.polar_error_at_points_pct, 11)}"
                        f"{_pct_cell(a.polar_error_pct, 13)}"
                        f" {a.specular_share:>7.3g} {a.lobe_half_width_deg:>10.3g}"
                        f"{a.lobe_points_1hw:>9d}{a.lobe_points_2hw:>9d}  {word}")
        rows += _no_area_notes(self.angles)
        return rows

    def to_dict(self) -> dict:
        # a fit at one angle of incidence (which no material file holds) says so
        at = ({} if self.fitted_at_deg is None else
              {"fitted_at_gamma_deg": self.fitted_at_deg, "on_all_points": self.on_all_points})
        return {"trustworthy": self.trustworthy, "summary": self.summary(),
                "problems": self.problems(), "at_bound": list(self.at_bound),
                "ill_determined": list(self.ill_determined), "converged": self.converged,
                "saturated_gammas_deg": list(self.saturated_gammas_deg), **at,
                "clipped_readings": self.clipped[0] if self.clipped else 0,
                "angles": [a.to_dict() for a in self.angles]}


#: A verdict phrase lists at most this many angles of incidence one by one; beyond, it
#: gives their count and span and the worst three (a 50-angle table's verdict had listed
#: all 50, 6,000 characters on one line).
MAX_LISTED = 8


def _worst_error(a) -> float:
    """An angle's larger polar-area error (at the receivers or of the whole curve), for
    ordering; NaN counts as the smallest."""
    vals = [v for v in (a.polar_error_at_points_pct, a.polar_error_pct) if np.isfinite(v)]
    return max(vals, default=-np.inf)


def _listed(what: str, parts: list[str], angles, order) -> str:
    """``what`` at the angles of ``angles`` (one phrase of ``parts`` each), or, beyond
    :data:`MAX_LISTED`, at their count and span, with the three first by ``order``
    (ascending: the worst first)."""
    if len(parts) <= MAX_LISTED:
        return f"{what} at |gamma| = " + ", ".join(parts)
    g = [a.gamma_deg for a in angles]
    first = [parts[i] for i in np.argsort(np.asarray(order, float), kind="stable")[:3]]
    return (f"{what} at {len(parts)} angles of incidence (|gamma| {min(g):g}-{max(g):g} "
            "deg), the worst at |gamma| = " + ", ".join(first))


def _undersampled_text(angles) -> str:
    """The problem phrase of the angles whose lobe is under-sampled."""
    parts = [f"{a.gamma_deg:g} deg (half width {a.lobe_half_width_deg:.2g} deg, receivers up "
             f"to {a.lobe_receiver_gap_deg:.2g} deg apart across it; polar-area error "
             f"{a.polar_error_at_points_pct:.3g} % at the receivers, "
             f"{a.polar_error_pct:.3g} % of the whole curve)" for a in angles]
    step = min(a.step_needed_deg for a in angles)
    reach = max(2.0 * a.lobe_half_width_deg for a in angles)
    return (_listed("specular lobe under-sampled", parts, angles,
                    [-a.lobe_receiver_gap_deg for a in angles])
            + ": straight lines between the readings cannot follow it, so the polar-area "
            "error of the curve does not judge its shape there; a receiver step of at most "
            f"{step:g} deg within +-{reach:.2g} deg of the mirror would resolve it")


def _no_area_notes(angles) -> list[str]:
    """The footnote of the table's '-' cells: why an angle has no polar area."""
    out = []
    if any(a.no_area == "points" for a in angles):
        out.append("(-: a polar area needs two or more points at that angle of incidence)")
    for reason, text in (("zero", "all {n} readings are zero: an area error is relative to "
                                  "the measured area, and there is none"),
                         ("span", "its {n} readings stand at one receiver angle: they span "
                                  "no area")):
        for a in angles:
            if a.no_area == reason:
                out.append(f"(-: no polar area at |gamma| = {a.gamma_deg:g} deg: "
                           + text.format(n=a.n_points) + ")")
    return out


def _floor2(x: float) -> float:
    """``x > 0`` rounded down to two significant digits (a step "at most" must not round
    up past the value it stands for)."""
    if not (np.isfinite(x) and x > 0):
        return float("nan")
    scale = 10.0 ** (np.floor(np.log10(x)) - 1)
    return float(np.round(np.floor(x / scale * (1 + 1e-12)) * scale, 12))


def _lobe_sampling(theta, measured, model_fn, mirror, hw) -> tuple[float, float]:
    """Where the model's continuous curve departs from the measured points joined by
    straight lines beyond what it does at the receivers: the excess (percentage points of
    the measured polar area, as :func:`irreflect.metrics.polar_area_error` counts it)
    outside the lobe's window, from the receiver at or before ``mirror - 2 hw`` to the one
    at or after ``mirror + 2 hw``, and the widest gap between receivers in that window."""
    order = np.argsort(theta)
    theta, measured = theta[order], measured[order]
    below, above = theta[theta <= mirror - 2 * hw], theta[theta >= mirror + 2 * hw]
    lo = below[-1] if below.size else theta[0]
    hi = above[0] if above.size else theta[-1]
    inside = theta[(theta >= lo) & (theta <= hi)]
    gap = float(np.max(np.diff(inside))) if inside.size > 1 else float("inf")
    n_steps = max(int(np.ceil((theta[-1] - theta[0]) / 0.1)), 2)
    grid = np.unique(np.concatenate([np.linspace(theta[0], theta[-1], n_steps + 1), theta]))
    r_meas = np.interp(grid, theta, measured)
    r_points = np.interp(grid, theta, np.asarray(model_fn(theta), float))
    with np.errstate(over="ignore", invalid="ignore"):
        excess = (np.abs(r_meas**2 - np.asarray(model_fn(grid), float) ** 2)
                  - np.abs(r_meas**2 - r_points**2))
        excess = np.where((grid < lo) | (grid > hi), excess, 0.0)
        under = np.trapezoid(r_meas**2, np.radians(grid))
        outside = float(100.0 * np.trapezoid(excess, np.radians(grid)) / under)
    return outside, gap


def _cell(x: float, width: int) -> str:
    """A table cell: the number, or '-' where there is none."""
    return f"{x:>{width}.3g}" if np.isfinite(x) else f"{'-':>{width}}"


def _pct(x: float) -> str:
    """A polar-area error (%) in text: '> 1000' beyond what a relative error can say."""
    return metrics.format_polar_error(x)


def _pct_cell(x: float, width: int) -> str:
    """A table cell of a polar-area error (%): as :func:`_pct`, '-' where there is none."""
    # a leading space: a wide value still stands apart from the cell before it
    return f" {_pct(x):>{width - 1}}" if not np.isnan(x) else f"{'-':>{width}}"


def _num(x: float):
    return float(x) if np.isfinite(x) else None


def _lobe_laws(result, g_abs_deg):
    """The specular share, the specular index and the diffuse index at each |gamma| (NaN
    where the model has none): the two-lobe family, single-lobe (one lobe: no diffuse)
    and Phong (diffuse index 1)."""
    p = result.params
    cg = np.cos(np.radians(g_abs_deg))
    nan = np.full(cg.shape, np.nan)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        if {"u_as", "v_as", "u_ns", "v_ns", "u_nd", "v_nd"} <= p.keys():
            return (specular_share(p["u_as"], p["v_as"], cg), p["u_ns"] * cg ** p["v_ns"],
                    p["u_nd"] * cg ** p["v_nd"])
        if result.model.startswith("phong") and {"k_s", "n"} <= p.keys():
            return np.full(cg.shape, p["k_s"]), np.full(cg.shape, p["n"]), np.ones(cg.shape)
        if result.model.startswith("single-lobe") and "n" in p:
            return np.ones(cg.shape), np.full(cg.shape, p["n"]), nan
    return nan, nan, nan


def _sampling(result, gamma_deg, theta_deg, g, hw, matters, polar) -> dict:
    """The fields of one angle that say how its receivers sample it: why it has no polar
    area, and whether its lobe is under-sampled (see the module docstring; ``polar``: the
    polar-area errors of the curve and at the receivers). An angle whose error at the
    receivers is beyond :data:`POLAR_ERROR_LIMIT` does not reproduce its shape whatever
    lies between them, and is not called under-sampled."""
    # the rows polar_area_errors compared at |gamma| = g (the last signed gamma of that size)
    signed = [x for x in sorted(np.unique(gamma_deg), key=abs) if abs(abs(x) - g) <= 1e-9]
    sel = gamma_deg == signed[-1]
    theta, power = theta_deg[sel], np.asarray(result.power, float)[sel]
    out = {"no_area": ("points" if sel.sum() < 2 else "span" if np.ptp(theta) <= 0
                       else "zero" if not np.any(power) else "")}
    curve, at_points = polar
    if not (matters and np.isfinite(hw) and hw > 0 and at_points <= POLAR_ERROR_LIMIT
            and curve - at_points > UNMEASURED_LIMIT):
        return out
    outside, gap = _lobe_sampling(
        theta, power, lambda t: result.predict(np.full_like(t, signed[-1]), t),
        -float(signed[-1]), hw)
    out["lobe_receiver_gap_deg"] = gap
    out["lobe_undersampled"] = bool(outside <= UNMEASURED_LIMIT and gap > hw / 2.0)
    return out


def fit_verdict(result) -> FitVerdict:
    """The verdict of a :class:`irreflect.fitting.FitResult` (see the module docstring)."""
    gamma_deg = np.asarray(result.gamma_deg, float)
    theta_deg = np.asarray(result.theta_deg, float)
    errors = metrics.polar_area_errors(gamma_deg, theta_deg, result.power, result.predict,
                                       model_sampling="continuous")
    at_points = metrics.polar_area_errors(gamma_deg, theta_deg, result.power, result.predict)
    g_abs = np.array(sorted({float(abs(g)) for g in gamma_deg}))
    share, n_s, n_d = _lobe_laws(result, g_abs)
    angles = []
    for i, g in enumerate(g_abs):
        sel = np.abs(np.abs(gamma_deg) - g) <= 1e-9
        # the mirror direction of each of the angle's rows (its own sign of gamma)
        off = np.abs(theta_deg[sel] + gamma_deg[sel])
        hw = float(np.degrees(np.arccos(2.0 ** (-1.0 / n_s[i])))) if n_s[i] > 0 else np.nan
        matters = False
        if np.isfinite(hw) and np.isfinite(share[i]):
            peak = share[i] * (n_s[i] + 1.0)
            diffuse = ((1.0 - share[i]) * (n_d[i] + 1.0) * np.cos(np.radians(g)) ** n_d[i]
                       if np.isfinite(n_d[i]) else 0.0)
            matters = bool(peak >= SIGNIFICANT * diffuse and peak > 0)
        angles.append(AngleVerdict(
            gamma_deg=float(g), n_points=int(sel.sum()),
            polar_error_pct=float(errors.get(float(g), np.nan)),
            polar_error_at_points_pct=float(at_points.get(float(g), np.nan)),
            specular_share=float(share[i]), lobe_half_width_deg=hw,
            lobe_points_1hw=int(np.sum(off <= hw)) if np.isfinite(hw) else 0,
            lobe_points_2hw=int(np.sum(off <= 2 * hw)) if np.isfinite(hw) else 0,
            lobe_matters=matters,
            **_sampling(result, gamma_deg, theta_deg, float(g), hw, matters,
                        (errors.get(float(g), np.nan), at_points.get(float(g), np.nan)))))
    on_all = getattr(result, "on_all_points", None)
    return FitVerdict(angles=tuple(angles), at_bound=tuple(result.at_bound),
                      ill_determined=tuple(result.ill_determined),
                      converged=bool(result.converged),
                      saturated_gammas_deg=tuple(float(x) for x in
                                                 result.saturated_gammas_deg),
                      fitted_at_deg=float(g_abs[0]) if on_all and g_abs.size == 1 else None,
                      on_all_points=dict(on_all) if on_all else None,
                      clipped=_clipped(gamma_deg, result.power))


def _clipped(gamma_deg, power) -> tuple:
    """:attr:`FitVerdict.clipped` of a fit's readings."""
    from .data import saturated_readings

    found = saturated_readings(gamma_deg, power)
    return () if found is None else (found[0], int(np.size(power)), found[1])
