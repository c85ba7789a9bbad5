"""The :class:`Protocol` object and the paper's 12-point protocol (section 4.3, Eqs. 23-34).

Conventions (the paper's): angles in degrees from the surface normal; the angle of
incidence ``gamma`` is negative on the source side; the receiver angle ``theta`` is
signed and the mirror (specular) direction is ``theta = -gamma``. Angles of incidence may
be given as magnitudes (all >= 0), as :mod:`irreflect.data` also accepts them: they are
then read as ``gamma = -|gamma|``. Mixing signs is refused as ambiguous.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from ..data import MIRRORED_FRAME, DataNotice
from ..errors import IrreflectError, unknown_name
from ..validation import short_list

#: What each point of a protocol is for.
PURPOSES = ("mirror", "lobe_width", "diffuse", "central", "optimised", "custom")

#: The rule of :func:`paper_protocol`, as written into exported protocols.
PAPER_RULE = (
    "paper section 4.3 (Eqs. 23-34): for the smallest and largest |gamma|, theta = -gamma "
    "(mirror), -gamma -/+ mirror_offset (lobe_width), -gamma -/+ wide_offset (diffuse); for "
    "the middle gamma, theta = gamma + central_offset and -gamma + central_offset (central). "
    "A theta outside the tool's range is clamped to the nearest limit (as the paper says). "
    "A clamped point closer than min_separation to an earlier point of the same gamma "
    "coincides with it and is replaced by the reachable theta farthest from that gamma's "
    "mirror direction that keeps min_separation from every other point of that gamma (ties: "
    "the side opposite the requested one, then the smaller theta); for gamma = -60 and limits "
    "+-70 this gives the paper's -70 for the requested +120. A lobe_width point clamped "
    "closer than min_separation to the mirror point, or a mirror direction outside the "
    "range, is refused: the tool cannot measure that lobe."
)

#: How :meth:`Protocol.in_measurement_order` orders points, as written into exports.
ORDER_RULE = (
    "measurement order: each angle of incidence is set once, by increasing |gamma| (changing "
    "gamma is the slow step); within one gamma the receiver sweeps theta monotonically, in "
    "the direction that starts nearest to where the previous sweep ended (the directions are "
    "chosen together to minimise the total receiver travel; ties ascending). Assumes the "
    "receiver angle is set independently of gamma (separate source and receiver arms)."
)

_EPS = 1e-9


def floor_sig(x: float, digits: int = 2) -> float:
    """``x > 0`` rounded *down* to ``digits`` significant digits (a limit stated as "at
    most" must not round up past the value it stands for): 0.617 -> 0.61."""
    x = float(x)
    if not (np.isfinite(x) and x > 0):
        return x
    scale = 10.0 ** (np.floor(np.log10(x)) - digits + 1)
    return float(np.round(np.floor(x / scale * (1 + 1e-12)) * scale, 12))


def _clean(x: float) -> float:
    """Round away binary noise (e.g. 69.99999999) and turn -0.0 into 0.0."""
    return float(np.round(float(x), 9)) + 0.0


@dataclass(frozen=True)
class Protocol:
    """A list of (gamma, theta) settings to measure, with what each one is for.

    Attributes
    ----------
    gamma_deg, theta_deg : ndarray, degrees
        The settings (paper convention: gamma <= 0, mirror direction theta = -gamma).
    purpose : tuple of str
        One of :data:`PURPOSES` per point.
    requested_theta_deg : ndarray, degrees
        The angle the rule asked for before clamping or replacement (NaN if not applicable).
    adjustment : tuple of str
        ``""``, ``"clamped"`` or ``"replaced"`` per point.
    theta_min, theta_max : float, degrees
        The receiver range of the tool the protocol was made for (NaN if unknown).
    kind : str
        ``"paper"``, ``"optimised"`` or ``"file"``.
    rule : str
        How the points were chosen (exported with the protocol).
    settings : dict
        The parameters of the rule (offsets, model, seed, ...).
    order : str
        ``"paper"`` (the order of the paper's Eqs. 27-34 and Table 1) or ``"measurement"``.
    notes : tuple of str
        What the rule did that a user should know (clamps, replacements).
    """

    gamma_deg: np.ndarray
    theta_deg: np.ndarray
    purpose: tuple[str, ...]
    requested_theta_deg: np.ndarray
    adjustment: tuple[str, ...]
    theta_min: float = float("nan")
    theta_max: float = float("nan")
    kind: str = "custom"
    rule: str = ""
    settings: dict = field(default_factory=dict)
    order: str = "given"
    notes: tuple[str, ...] = ()
    name: str = "protocol"

    @property
    def n_points(self) -> int:
        return int(self.gamma_deg.size)

    @property
    def gammas(self) -> np.ndarray:
        """Distinct angles of incidence, by increasing magnitude."""
        g = np.unique(self.gamma_deg)
        return g[np.argsort(np.abs(g), kind="stable")]

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame({
            "gamma_deg": self.gamma_deg,
            "theta_deg": self.theta_deg,
            "purpose": list(self.purpose),
            "requested_theta_deg": self.requested_theta_deg,
            "adjustment": list(self.adjustment),
        })

    def take(self, index) -> Protocol:
        """The points ``index`` (an integer array), in that order."""
        index = np.asarray(index, int)
        return replace(
            self,
            gamma_deg=self.gamma_deg[index],
            theta_deg=self.theta_deg[index],
            purpose=tuple(self.purpose[i] for i in index),
            requested_theta_deg=self.requested_theta_deg[index],
            adjustment=tuple(self.adjustment[i] for i in index),
        )

    def in_measurement_order(self) -> Protocol:
        """The same points ordered to minimise arm moves (see :data:`ORDER_RULE`)."""
        out = self.take(measurement_permutation(self.gamma_deg, self.theta_deg))
        return replace(out, order="measurement")

    def receiver_travel(self) -> float:
        """Total receiver travel (degrees) when measured in the current order, counting
        only moves within one gamma setting and between consecutive settings."""
        return float(np.sum(np.abs(np.diff(self.theta_deg))))

    def gamma_changes(self) -> int:
        """How many times gamma changes when measured in the current order."""
        return int(np.count_nonzero(np.diff(self.gamma_deg)))


def measurement_permutation(gamma_deg, theta_deg) -> np.ndarray:
    """Indices that put points in measurement order (see :data:`ORDER_RULE`)."""
    gamma = np.asarray(gamma_deg, float)
    theta = np.asarray(theta_deg, float)
    if gamma.size == 0:
        return np.zeros(0, int)
    levels = sorted(np.unique(gamma), key=lambda g: (abs(g), g))
    groups = []
    for g in levels:
        idx = np.nonzero(gamma == g)[0]
        groups.append(idx[np.argsort(theta[idx], kind="stable")])
    # dynamic programme over sweep directions: state = direction of the last sweep
    # (0 ascending -> ends at the group's max, 1 descending -> ends at its min)
    lo = [theta[g[0]] for g in groups]
    hi = [theta[g[-1]] for g in groups]
    cost = [0.0, 0.0]
    back = []
    for k in range(1, len(groups)):
        ends = (hi[k - 1], lo[k - 1])
        new, choice = [], []
        for start in (lo[k], hi[k]):  # ascending starts at lo, descending at hi
            options = [cost[d] + abs(ends[d] - start) for d in (0, 1)]
            d = int(np.argmin(options))
            new.append(options[d])
            choice.append(d)
        cost = new
        back.append(choice)
    last = int(np.argmin(cost))
    dirs = [last]
    for choice in reversed(back):
        dirs.append(choice[dirs[-1]])
    dirs.reverse()
    return np.concatenate([g if d == 0 else g[::-1] for g, d in zip(groups, dirs, strict=True)])


# ----------------------------------------------------------------------------- validation
def normalise_gammas(gammas_deg, *, what: str = "angles of incidence") -> np.ndarray:
    """Angles of incidence in the paper's convention (<= 0, degrees).

    All >= 0: read as magnitudes (``gamma = -|gamma|``). All <= 0: kept. Mixed signs,
    non-finite values or ``|gamma| >= 90`` raise :class:`IrreflectError`.
    """
    try:
        arr = np.asarray(gammas_deg, float).ravel()
    except (TypeError, ValueError) as exc:
        raise IrreflectError(
            f"{what} must be numbers in degrees; found {gammas_deg!r}"
        ) from exc
    if arr.size == 0:
        raise IrreflectError(f"expected at least one of the {what} (degrees); found none")
    if not np.all(np.isfinite(arr)):
        raise IrreflectError(f"{what} must be finite numbers in degrees; found {arr.tolist()}")
    if np.any(np.abs(arr) >= 90):
        bad = arr[np.abs(arr) >= 90][0]
        raise IrreflectError(
            f"{what} must lie strictly between -90 and 90 degrees; found {bad:g}: angles are "
            "measured from the surface normal"
        )
    if np.any(arr > 0) and np.any(arr < 0):
        raise IrreflectError(
            f"{what} {', '.join(f'{g:g}' for g in arr)} mix positive and negative values, which "
            "is ambiguous: give all as magnitudes (>= 0) or all in the paper's convention (<= 0)"
        )
    return np.array([_clean(-abs(g)) for g in arr])


def check_limits(theta_min: float, theta_max: float) -> tuple[float, float]:
    """Validate a receiver range (degrees): finite, -90 < theta_min < theta_max < 90."""
    try:
        lo, hi = float(theta_min), float(theta_max)
    except (TypeError, ValueError) as exc:
        raise IrreflectError(
            f"receiver limits must be numbers in degrees; found {theta_min!r}, {theta_max!r}"
        ) from exc
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise IrreflectError(f"receiver limits must be finite; found {lo:g}, {hi:g}")
    if not -90 < lo < hi < 90:
        raise IrreflectError(
            f"receiver limits must satisfy -90 < theta_min < theta_max < 90 degrees; found "
            f"theta_min = {lo:g}, theta_max = {hi:g}: give the tool's real range, e.g. -70 70"
        )
    return lo, hi


# ----------------------------------------------------------------------------- the paper's protocol
def _coincides(value: float, taken: list[float], min_sep: float) -> bool:
    return any(abs(value - p) < min_sep - _EPS for p in taken)


def _replacement(mirror: float, requested: float, taken: list[float], lo: float, hi: float,
                 min_sep: float) -> float | None:
    """The reachable theta farthest from ``mirror`` keeping ``min_sep`` from ``taken``.

    The optimum of |c - mirror| over the feasible set (the range minus open intervals of
    half-width min_sep around taken points) lies at a range limit or at an interval edge,
    so only those candidates are tried.
    """
    candidates = {lo, hi}
    for p in taken:
        candidates |= {p - min_sep, p + min_sep}
    feasible = [c for c in candidates
                if lo - _EPS <= c <= hi + _EPS and not _coincides(c, taken, min_sep)]
    if not feasible:
        return None
    side = np.sign(requested - mirror)

    def key(c):
        opposite = np.sign(c - mirror) == -side
        return (-round(abs(c - mirror), 9), 0 if opposite else 1, c)

    return _clean(min(feasible, key=key))


def _mirror_in_range(g, lo, hi) -> float:
    """The mirror direction of ``g``, refused when the tool's range ``[lo, hi]`` misses it."""
    mirror = _clean(-g)
    if not lo - _EPS <= mirror <= hi + _EPS:
        raise IrreflectError(
            f"gamma {g:g}: its mirror direction theta = {mirror:g} lies outside the tool's "
            f"receiver range [{lo:g}, {hi:g}], so the specular peak cannot be measured: "
            f"choose |gamma| within the range or widen it"
        )
    return mirror


def _three_gammas(gammas_deg, limits, needs: str, listed):
    """Three distinct angles of incidence (by magnitude) and the receiver range, checked;
    ``needs``: the refusal's first words, ``listed``: how it lists what was given."""
    gammas = normalise_gammas(gammas_deg)
    mags = np.abs(gammas)
    if gammas.size != 3 or np.unique(mags).size != 3:
        raise IrreflectError(
            f"{needs}; found {listed(np.asarray(gammas_deg, float).ravel())}: "
            "give three, e.g. --gammas -20 -40 -60"
        )
    return tuple(gammas[np.argsort(mags)]), check_limits(*limits)


def _paper_arguments(gammas_deg, theta_min, theta_max, offsets, min_separation):
    """:func:`paper_protocol`'s arguments checked: (the three angles of incidence by
    magnitude, the receiver range, the coincidence distance)."""
    mirror_offset, wide_offset, central_offset = offsets
    gammas, (lo, hi) = _three_gammas(
        gammas_deg, (theta_min, theta_max),
        "the paper's protocol needs exactly three distinct angles of incidence (Eq. 23)",
        lambda values: short_list(values, fmt=lambda g: f"{g:g}"))
    named = {"mirror_offset": mirror_offset, "wide_offset": wide_offset,
             "central_offset": central_offset}
    for key, value in named.items():
        if not (np.isfinite(value) and 0 < value < 180):
            raise IrreflectError(f"{key} must be between 0 and 180 degrees; found {value:g}")
    if not mirror_offset < wide_offset:
        raise IrreflectError(
            f"mirror_offset ({mirror_offset:g}) must be smaller than wide_offset "
            f"({wide_offset:g}): the lobe-width points lie inside the diffuse ones"
        )
    min_sep = mirror_offset / 2 if min_separation is None else float(min_separation)
    if not 0 <= min_sep <= mirror_offset:
        raise IrreflectError(
            f"min_separation must be between 0 and mirror_offset ({mirror_offset:g}); "
            f"found {min_sep:g}"
        )
    return gammas, (lo, hi), min_sep


#: deg: a protocol point this close to the source direction (theta = gamma) is noted: a
#: goniometer's receiver there stands in the beam (at normal incidence the mirror is the
#: source direction).
SOURCE_NEAR_DEG = 5.0


def _source_notes(gammas, thetas, purposes) -> list[str]:
    """A note per point within :data:`SOURCE_NEAR_DEG` of the source direction (theta =
    gamma): a receiver there stands in the beam."""
    return [f"gamma {g:g}: the {kind} point theta {t:g} is within {SOURCE_NEAR_DEG:g} deg of "
            "the source direction (theta = gamma): a receiver there blocks the beam (measure "
            f"it through a beam splitter, or choose |gamma| >= {SOURCE_NEAR_DEG:g})"
            for g, t, kind in zip(gammas, thetas, purposes, strict=True)
            if abs(t - g) < SOURCE_NEAR_DEG]


def paper_protocol(gammas_deg, theta_min: float = -70.0, theta_max: float = 70.0, *,
                   mirror_offset: float = 10.0, wide_offset: float = 60.0,
                   central_offset: float = 20.0, min_separation: float | None = None,
                   name: str = "paper-12pt") -> Protocol:
    """The paper's 12-point protocol for a tool with the given receiver range.

    Section 4.3, Eqs. 23-34: three angles of incidence ``|gamma_1| < |gamma_2| < |gamma_3|``;
    for the extreme ones the mirror angle ``-gamma`` (Eqs. 27-28), two points
    ``+-mirror_offset`` around it (Eqs. 29-30, lobe width) and two ``+-wide_offset`` from it
    (Eqs. 31-32, diffuse component); for the central one ``gamma_2 + central_offset`` and
    ``-gamma_2 + central_offset`` (Eqs. 33-34). Clamping and the coincidence rule are
    described in :data:`PAPER_RULE`. With gammas -20/-40/-60 and limits +-70 the result is
    the paper's Table 1, in its order.

    Parameters
    ----------
    gammas_deg : three numbers, degrees
        Angles of incidence, in any order; all <= 0 (paper convention) or all >= 0
        (magnitudes, read as ``-|gamma|``).
    theta_min, theta_max : float, degrees
        The receiver range the tool can set.
    mirror_offset, wide_offset, central_offset : float, degrees
        The paper's 10, 60 and 20 degrees.
    min_separation : float, degrees, optional
        Two points of one gamma closer than this coincide (default ``mirror_offset / 2``).

    Returns
    -------
    Protocol
        12 points in the paper's order (Table 1); see :meth:`Protocol.in_measurement_order`.

    Raises
    ------
    IrreflectError
        Fewer or more than three distinct angles of incidence, ``|angle| >= 90``, bad
        offsets, a mirror direction outside the range, or a range too narrow for the
        lobe-width points or for five separated points.
    """
    (g1, g2, g3), (lo, hi), min_sep = _paper_arguments(
        gammas_deg, theta_min, theta_max, (mirror_offset, wide_offset, central_offset),
        min_separation)

    gamma_out, theta_out, purpose, requested, adjustment, notes = [], [], [], [], [], []

    def place(g, mirror, wanted, kind, taken, replaceable):
        clamped = _clean(min(max(wanted, lo), hi))
        adj = "clamped" if abs(clamped - wanted) > _EPS else ""
        if adj:
            limit = "theta_max" if wanted > hi else "theta_min"
            notes.append(f"gamma {g:g}: {kind} theta {wanted:g} is outside the tool range, "
                         f"clamped to {limit} = {clamped:g}")
        value = clamped
        if _coincides(clamped, taken, min_sep):
            if not replaceable:
                raise IrreflectError(
                    f"gamma {g:g}: the lobe-width point theta = {wanted:g} is outside the tool "
                    f"range [{lo:g}, {hi:g}] and clamping it leaves it within {min_sep:g} deg of "
                    f"the mirror point {mirror:g}: no room to measure the lobe width; choose a "
                    "smaller |gamma| or a tool with a wider range"
                )
            value = _replacement(mirror, wanted, taken, lo, hi, min_sep)
            if value is None:
                raise IrreflectError(
                    f"gamma {g:g}: the tool range [{lo:g}, {hi:g}] is too narrow to place the "
                    f"protocol's points at least {min_sep:g} deg apart: widen the range or "
                    "lower min_separation"
                )
            adj = "replaced"
            notes.append(f"gamma {g:g}: {kind} theta {wanted:g} clamped to {clamped:g} coincides "
                         f"with another point of that gamma; replaced by {value:g}, the reachable "
                         f"angle farthest from the mirror direction {mirror:g}")
        taken.append(value)
        gamma_out.append(g)
        theta_out.append(value)
        purpose.append(kind)
        requested.append(_clean(wanted))
        adjustment.append(adj)

    for g in (g1, None, g3):
        if g is None:  # central gamma (Eqs. 33-34)
            taken: list[float] = []
            mirror = _clean(-g2)
            place(g2, mirror, _clean(g2 + central_offset), "central", taken, True)
            place(g2, mirror, _clean(-g2 + central_offset), "central", taken, True)
            continue
        mirror = _mirror_in_range(g, lo, hi)
        taken = []
        place(g, mirror, mirror, "mirror", taken, False)
        place(g, mirror, _clean(mirror - mirror_offset), "lobe_width", taken, False)
        place(g, mirror, _clean(mirror + mirror_offset), "lobe_width", taken, False)
        place(g, mirror, _clean(mirror - wide_offset), "diffuse", taken, True)
        place(g, mirror, _clean(mirror + wide_offset), "diffuse", taken, True)

    notes += _source_notes(gamma_out, theta_out, purpose)
    return Protocol(
        gamma_deg=np.array(gamma_out, float),
        theta_deg=np.array(theta_out, float),
        purpose=tuple(purpose),
        requested_theta_deg=np.array(requested, float),
        adjustment=tuple(adjustment),
        theta_min=lo,
        theta_max=hi,
        kind="paper",
        rule=PAPER_RULE,
        settings={"gammas_deg": [float(g1), float(g2), float(g3)],
                  "mirror_offset": mirror_offset, "wide_offset": wide_offset,
                  "central_offset": central_offset, "min_separation": min_sep},
        order="paper",
        notes=tuple(notes),
        name=name,
    )


def protocol_from_frame(df: pd.DataFrame, source: str = "protocol", *,
                        name: str | None = None) -> Protocol:
    """A protocol from a table with ``gamma_deg, theta_deg`` and optional ``purpose``
    (extra columns, such as a filled-in ``power``, are ignored)."""
    cols = {str(c).strip(): c for c in df.columns}
    missing = [c for c in ("gamma_deg", "theta_deg") if c not in cols]
    if missing:
        raise IrreflectError(
            f"{source}: missing column '{missing[0]}': a protocol needs columns gamma_deg, "
            f"theta_deg (optional purpose); found {short_list(map(str, df.columns)) or 'none'}"
        )
    if len(df) == 0:
        raise IrreflectError(f"{source}: the protocol has no rows: expected at least one point")
    out = {}
    for col in ("gamma_deg", "theta_deg"):
        values = pd.to_numeric(df[cols[col]], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            raise IrreflectError(
                f"{source}: column '{col}' must hold numbers in degrees; found "
                f"'{df[cols[col]].iloc[i]}' in data row {i + 1}: fix that row"
            )
        if np.any(np.abs(values) >= 90):
            i = int(np.nonzero(np.abs(values) >= 90)[0][0])
            raise IrreflectError(
                f"{source}: {col} must lie strictly between -90 and 90 degrees; found "
                f"{values[i]:g} in data row {i + 1}"
            )
        out[col] = values
    gamma = normalise_gammas(out["gamma_deg"], what=f"{source}: gamma_deg values")
    if "purpose" in cols:
        purpose = tuple(str(p) if isinstance(p, str) and p.strip() else "custom"
                        for p in df[cols["purpose"]])
    else:
        purpose = ("custom",) * len(df)
    raw_theta = out["theta_deg"]
    if _mirrored_frame(out["gamma_deg"], raw_theta, purpose):
        raw_theta = -raw_theta
        warnings.warn(f"{source}: all gamma_deg >= 0 and its mirror points stand at theta = "
                      f"-gamma: {MIRRORED_FRAME}", DataNotice, stacklevel=2)
    theta = np.array([_clean(t) for t in raw_theta])
    key = pd.DataFrame({"g": gamma, "t": theta})
    if key.duplicated().any():
        i = int(np.nonzero(key.duplicated().to_numpy())[0][0])
        raise IrreflectError(
            f"{source}: point ({gamma[i]:g}, {theta[i]:g}) appears twice (data row {i + 1}): "
            "a protocol lists each setting once"
        )
    return Protocol(
        gamma_deg=gamma, theta_deg=theta, purpose=purpose,
        requested_theta_deg=np.full(gamma.size, np.nan), adjustment=("",) * gamma.size,
        kind="file", rule=f"read from {source}", order="given", name=name or "protocol",
    )


def _mirrored_frame(gamma, theta, purpose) -> bool:
    """A protocol file in the paper's frame mirrored (the source on the positive side): all
    its gammas >= 0 and every ``mirror`` point at theta = -gamma in the file's own signs
    (read as magnitudes they would stand at theta = +gamma, on the source direction; a
    dense table is recognised by where its readings peak, a protocol by its mirror points)."""
    gamma, theta = np.asarray(gamma, float), np.asarray(theta, float)
    mirror = np.array([p == "mirror" for p in purpose]) & (gamma >= 1.0)
    if np.any(gamma < 0) or not mirror.any():
        return False
    return bool(np.all(np.abs(theta[mirror] + gamma[mirror])
                       < np.abs(theta[mirror] - gamma[mirror])))


# ----------------------------------------------------------------------------- glossy materials
#: The rule of :func:`glossy_protocol`, as written into exported protocols.
GLOSSY_LAYOUTS = ("paper", "balanced")
GLOSSY_RULE = (
    "glossy-aware 12 points (the paper's section 4.3 with lobe-sized offsets), layout 'paper': "
    "for the smallest and largest |gamma|, theta = -gamma (mirror), -gamma -/+ w(gamma) "
    "(lobe_width, w = the specular lobe's half width at half maximum, acos(2^(-1/n_s)), between "
    "min_lobe_offset and max_lobe_offset) and -gamma -/+ wide_offset (diffuse); for the middle "
    "gamma, theta = -gamma (mirror) and gamma + central_offset (central); layout 'balanced': at "
    "each gamma the mirror, -gamma + w toward the normal, and two diffuse angles (5-deg grid, "
    "max(15, 5 w) deg from the mirror, 10 deg from the source: nearest -gamma - wide_offset, "
    "and nearest the normal 30 deg from it). n_s(gamma) comes from "
    "a pilot scan's two-lobe fit (u_ns cos^v_ns(gamma)) or is given. With a pilot scan, every "
    "point is moved to the nearest angle the pilot measured at that gamma (a tool with fixed "
    "receiver positions), distinct points kept distinct. Points outside the receiver range "
    "are clamped as in the paper's rule, and a clamped point on top of another of its gamma "
    "is replaced as there (separation: half the lobe offset)."
)


def lobe_half_width_deg(index) -> np.ndarray:
    """Half width at half maximum (degrees) of a lobe ``cos^n`` (Eq. 3 inverted):
    ``acos(2^(-1/n))``. index : array-like, dimensionless, > 0."""
    n = np.asarray(index, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.degrees(np.arccos(np.power(2.0, -1.0 / n)))


def _glossy_arguments(gammas_deg, theta_min, theta_max, specular_index, limits, layout):
    """:func:`glossy_protocol`'s arguments checked: (the three angles of incidence by
    magnitude, the receiver range, the lobe-width offset of each). ``limits``:
    (min_lobe_offset, max_lobe_offset, wide_offset)."""
    min_lobe_offset, max_lobe_offset, wide_offset = limits
    gammas, (lo, hi) = _three_gammas(
        gammas_deg, (theta_min, theta_max),
        "the glossy protocol needs exactly three distinct angles of incidence",
        lambda values: ", ".join(f"{g:g}" for g in values))
    if not (0 < min_lobe_offset <= max_lobe_offset < wide_offset):
        raise IrreflectError(
            "lobe offsets must satisfy 0 < min_lobe_offset <= max_lobe_offset < wide_offset; "
            f"found {min_lobe_offset:g}, {max_lobe_offset:g}, {wide_offset:g}"
        )
    index_of = specular_index if callable(specular_index) else (lambda g: specular_index)
    g1, g2, g3 = gammas
    offsets = {}
    for g in (g1, g2, g3):
        n = float(index_of(float(g)))
        if not (np.isfinite(n) and n > 0):
            raise IrreflectError(
                f"the specular index at gamma {g:g} must be a positive number; found {n:g}: "
                "give --specular-index N or a pilot scan with a specular lobe"
            )
        offsets[g] = float(np.clip(lobe_half_width_deg(n), min_lobe_offset, max_lobe_offset))
    if layout not in GLOSSY_LAYOUTS:
        raise unknown_name("glossy protocol layout", str(layout), GLOSSY_LAYOUTS)
    return (g1, g2, g3), (lo, hi), offsets


def _replace_clamped(g, kind, wanted_value, taken, limits, separation):
    """A glossy protocol's point clamped onto another of its gamma, replaced by the
    reachable angle farthest from the mirror direction: (the angle, its note)."""
    wanted, value = wanted_value
    lo, hi = limits
    mirror = _clean(-g)
    other = _replacement(mirror, wanted, taken, lo, hi, separation)
    if other is None:
        raise IrreflectError(
            f"gamma {g:g}: the receiver range [{lo:g}, {hi:g}] has no room for the "
            f"{kind} point away from the others: widen the range")
    return other, (f"gamma {g:g}: {kind} theta {wanted:g} clamped to {value:g} coincides "
                   f"with another point of that gamma; replaced by {other:g}, the "
                   f"reachable angle farthest from the mirror direction {mirror:g}")


def _glossy_plan(gammas, offsets, limits, layout, wide_central):
    """The glossy protocol's wanted points ``(gamma, theta, purpose)`` in the order of
    ``gammas`` (by magnitude), before clamping."""
    g1, g2, g3 = gammas
    lo, hi = limits
    wide_offset, central_offset = wide_central
    plan = []
    for g in (g1, g2, g3):
        mirror = _mirror_in_range(g, lo, hi)
        w = offsets[g]
        if layout == "balanced":
            plan += [(g, mirror, "mirror"), (g, mirror - w, "lobe_width")]
            plan += [(g, t, "diffuse") for t in _diffuse_angles(g, w, lo, hi, wide_offset)]
        elif g == g2:
            plan += [(g, mirror, "mirror"), (g, g + central_offset, "central")]
        else:
            plan += [(g, mirror, "mirror"), (g, mirror - w, "lobe_width"),
                     (g, mirror + w, "lobe_width"), (g, mirror - wide_offset, "diffuse"),
                     (g, mirror + wide_offset, "diffuse")]
    order = {g1: 0, g2: 1, g3: 2}
    plan.sort(key=lambda p: order[p[0]])
    return plan


def glossy_protocol(gammas_deg, theta_min: float = -70.0, theta_max: float = 70.0, *,
                    specular_index, wide_offset: float = 60.0, central_offset: float = 20.0,
                    min_lobe_offset: float = 0.25, max_lobe_offset: float = 10.0,
                    layout: str = "paper", available: dict | None = None,
                    name: str = "glossy-12pt") -> Protocol:
    """12 points for a glossy material: the paper's plan with lobe-sized offsets.

    The paper's lobe-width points sit 10 deg either side of the mirror (Eqs. 29-30); a gloss
    paint's specular lobe is a degree wide or less, so they see only the diffuse floor and
    the lobe is never measured. Here they sit at the lobe's half width at half maximum,
    where the lobe's shape is best resolved, and the middle angle of incidence also gets a
    mirror point (see :data:`GLOSSY_RULE`).

    Parameters
    ----------
    gammas_deg : three numbers, degrees
        Angles of incidence (<= 0, or magnitudes).
    theta_min, theta_max : float, degrees
        The receiver range of the tool.
    specular_index : float or callable
        The specular lobe index ``n_s``, or a function ``n_s(gamma_deg)`` (e.g. from a
        pilot scan's fit: ``u_ns cos^v_ns(gamma)``).
    wide_offset, central_offset : float, degrees
        The paper's diffuse (60) and central (20) offsets.
    min_lobe_offset, max_lobe_offset : float, degrees
        Limits of the lobe-width offset (the goniometer's resolution; the paper's 10).
    layout : ``"paper"`` or ``"balanced"``
        ``"paper"``: the paper's 5 + 2 + 5 points (for the smallest and largest |gamma|:
        mirror, mirror -/+ w, mirror -/+ wide_offset; for the middle one: mirror and
        gamma + central_offset). ``"balanced"``: 4 points at each gamma (mirror, mirror - w
        toward the normal, and two diffuse angles away from the lobe and the source), which
        gives the lobe's height and width at all three angles.
    available : dict, optional
        ``gamma_deg -> measured theta_deg`` of a pilot scan: every point is moved to the
        nearest of these (the tool can only stand there), keeping points distinct.
    """
    (g1, g2, g3), (lo, hi), offsets = _glossy_arguments(
        gammas_deg, theta_min, theta_max, specular_index,
        (min_lobe_offset, max_lobe_offset, wide_offset), layout)
    plan = _glossy_plan((g1, g2, g3), offsets, (lo, hi), layout, (wide_offset, central_offset))
    gamma_out, theta_out, purpose, requested, adjustment, notes = [], [], [], [], [], []
    taken: dict[float, list[float]] = {}
    clamped = []
    for g, wanted, kind in plan:
        wanted = _clean(wanted)
        value = _clean(min(max(wanted, lo), hi))
        adj = "clamped" if abs(value - wanted) > _EPS else ""
        clamped.append(bool(adj))
        if adj:
            notes.append(f"gamma {g:g}: {kind} theta {wanted:g} is outside the tool range, "
                         f"clamped to {value:g}")
        if available is not None:
            value, moved = _nearest_free(available, g, value, taken.get(g, []), lo, hi)
            if moved:
                adj = "snapped"
        elif adj and _coincides(value, taken.get(g, []), 0.5 * offsets[g]):
            # a clamped point on top of another of its gamma: the paper's coincidence rule
            # with half the lobe offset as the separation (see PAPER_RULE)
            other, note = _replace_clamped(g, kind, (wanted, value), taken.get(g, []),
                                           (lo, hi), 0.5 * offsets[g])
            notes.append(note)
            value, adj = other, "replaced"
        taken.setdefault(g, []).append(value)
        gamma_out.append(g)
        theta_out.append(value)
        purpose.append(kind)
        requested.append(wanted)
        adjustment.append(adj)
    gamma_arr, theta_arr = np.array(gamma_out, float), np.array(theta_out, float)
    placed = lobe_placement(gamma_arr, theta_arr, purpose)
    settings = {"gammas_deg": [float(g1), float(g2), float(g3)],
                "designed_lobe_offsets_deg": {f"{g:g}": round(w, 4) for g, w in offsets.items()},
                "lobe_offsets_deg": {f"{g:g}": [round(x, 4) for x in placed[g]["lobe"]]
                                     for g in (g1, g2, g3)},
                "mirror_offsets_deg": {f"{g:g}": round(placed[g]["mirror"], 4)
                                       for g in (g1, g2, g3)},
                "wide_offset": wide_offset, "central_offset": central_offset,
                "min_lobe_offset": min_lobe_offset, "max_lobe_offset": max_lobe_offset,
                "layout": layout, "snapped_to_pilot": available is not None}
    if available is not None:
        # points clamped to the receiver range have their own notes: the grid is judged on
        # the others
        free = ~np.array(clamped, bool)
        problem = _placement_problem(
            offsets, lobe_placement(gamma_arr[free], theta_arr[free],
                                    [p for p, f in zip(purpose, free, strict=True) if f]),
            available)
        if problem is not None:
            text, step = problem
            notes.append(text)
            settings["placement_warning"] = text
            settings["receiver_step_needed_deg"] = None if step is None else floor_sig(step)
    return Protocol(
        gamma_deg=gamma_arr,
        theta_deg=theta_arr,
        purpose=tuple(purpose),
        requested_theta_deg=np.array(requested, float),
        adjustment=tuple(adjustment),
        theta_min=lo,
        theta_max=hi,
        kind="glossy",
        rule=GLOSSY_RULE,
        settings=settings,
        order="paper",
        notes=tuple(notes),
        name=name,
    )


def lobe_placement(gamma_deg, theta_deg, purpose) -> dict[float, dict]:
    """Where a protocol's mirror and lobe-width points stand, as written: per angle of
    incidence ``gamma`` (degrees), ``{"mirror": |theta - (-gamma)| of its mirror point (NaN
    without one), "lobe": sorted |theta - (-gamma)| of its lobe_width points}``."""
    gamma_deg = np.asarray(gamma_deg, float)
    theta_deg = np.asarray(theta_deg, float)
    out = {}
    for g in np.unique(gamma_deg):
        sel = gamma_deg == g
        off = np.abs(theta_deg[sel] + g)
        kinds = [p for p, s in zip(purpose, sel, strict=True) if s]
        mirror = [o for o, k in zip(off, kinds, strict=True) if k == "mirror"]
        out[float(g)] = {"mirror": float(min(mirror)) if mirror else float("nan"),
                         "lobe": sorted(float(_clean(o)) for o, k in zip(off, kinds, strict=True)
                                        if k == "lobe_width")}
    return out


def _placement_problem(designed: dict, placed: dict, available: dict):
    """``(warning, receiver step needed or None)`` when a pilot's receivers cannot place the designed
    points (a lobe-width point outside ``[w/2, 3w/2]`` of the mirror, or a mirror point more
    than ``w/2`` off it, ``w`` the designed offset), else None. A receiver grid of step
    ``w`` has a receiver within ``w/2`` of any target, so ``w`` is the step needed."""
    bad = []
    for g, w in designed.items():
        where = placed.get(float(g))
        if where is None:
            continue
        lobe_off = [o for o in where["lobe"] if not 0.5 * w - _EPS <= o <= 1.5 * w + _EPS]
        mirror_off = where["mirror"] > 0.5 * w + _EPS
        if lobe_off or mirror_off:
            bad.append(g)
    if not bad:
        return None
    w_bad = [designed[g] for g in bad]
    lobes = [o for g in bad for o in placed[float(g)]["lobe"]]
    mirrors = [placed[float(g)]["mirror"] for g in bad if np.isfinite(placed[float(g)]["mirror"])]
    gaps = []
    for g in bad:
        thetas = None
        for key, values in available.items():
            if abs(float(key) - g) <= 1e-6:
                thetas = np.sort(np.asarray(values, float))
        if thetas is not None and thetas.size >= 2:
            gap = _gap_at(thetas, -g)
            if np.isfinite(gap):
                gaps.append(gap)
    step = min(w_bad)

    def span(values, digits=3):
        lo, hi = f"{min(values):.{digits}g}", f"{max(values):.{digits}g}"
        return lo if lo == hi else f"{lo}-{hi}"

    shadow = _source_shadow(designed, available, bad)
    mirror_shadowed = {g for g, t, _a, _b in shadow if abs(t + g) <= _EPS}
    fine = len(gaps) == len(bad) and all(  # receivers close enough at every mirror
        gap <= designed[g] + _EPS or g in mirror_shadowed
        for g, gap in zip(bad, gaps, strict=True))
    if fine and {g for g, *_ in shadow} == set(bad):
        # the receivers are fine near the mirror: a lobe-width point falls where the source
        # stands (theta = gamma), and no finer receiver step places it there
        where = "; ".join(f"at gamma {g:g} the point designed at theta {t:g} falls in the "
                          f"pilot's gap from {a:g} to {b:g} deg around the source direction "
                          f"(theta = gamma), where no receiver can stand"
                          for g, t, a, b in shadow)
        text = (f"the designed points cannot all be placed: {where}; the lobe-width points "
                "stand " + span(lobes) + " deg from the mirror, designed " + span(w_bad)
                + " deg" + (f", mirror points up to {max(mirrors):.3g} deg off it"
                            if mirrors and max(mirrors) > _EPS else "") + ". A "
                "finer receiver step does not mend it; the adaptive campaign (irreflect "
                "next) chooses readings the instrument can take. The file holds the placed "
                "points")
        return text, None
    text = (f"the pilot's receiver grid cannot place the designed points at gamma "
            f"{', '.join(f'{g:g}' for g in bad)}: lobe-width points designed {span(w_bad)} deg "
            "from the mirror stand " + (f"{span(lobes)} deg from it" if lobes else "nowhere")
            + (f", mirror points up to {max(mirrors):.3g} deg off it" if mirrors else "")
            + (f" (the pilot's receivers are {span(gaps)} deg apart at the mirror)" if gaps
               else "")
            + f"; placing them needs a receiver step of at most {floor_sig(step):g} deg within "
            f"+-{2 * max(w_bad):.2g} deg of the mirror. The file holds the placed points")
    return text, step


def _source_shadow(designed: dict, available: dict, bad) -> list:
    """The targets (the mirror, and the mirror -+ the designed offset) of the ``bad``
    angles of incidence that no pilot receiver comes within half the offset of, and whose
    gap between receivers holds the source direction (theta = gamma): ``(gamma, target,
    gap start, gap end)`` each. A held-out off-specular table's pilot, receivers 1 deg
    apart, had none from -11 to 1 deg at gamma -5, so the point 10 deg from the mirror
    toward the normal (theta -5) stood 16 deg from it; the warning asked for a finer
    receiver step. At normal incidence the mirror is the source direction (NIST's PTFE:
    no receiver from -5.7 to 5.7 deg at gamma 0)."""
    out = []
    for g in bad:
        w = designed[g]
        thetas = next((np.sort(np.asarray(v, float)) for k, v in available.items()
                       if abs(float(k) - g) <= 1e-6), None)
        if thetas is None or thetas.size < 2:
            continue
        for target in (-g - w, -g, -g + w):  # the lobe-width points and the mirror point
            if np.min(np.abs(thetas - target)) <= 0.5 * w + _EPS:
                continue
            i = int(np.searchsorted(thetas, target))
            if 0 < i < thetas.size and thetas[i - 1] < g < thetas[i]:
                out.append((float(g), _clean(target), float(thetas[i - 1]), float(thetas[i])))
    return out


def _gap_at(thetas: np.ndarray, target: float) -> float:
    """The spacing of sorted receiver angles around ``target``: the gap that brackets it
    (the larger neighbouring gap when a receiver stands on it)."""
    i = int(np.searchsorted(thetas, target))
    if i < thetas.size and abs(thetas[i] - target) <= _EPS:
        left = thetas[i] - thetas[i - 1] if i > 0 else 0.0
        right = thetas[i + 1] - thetas[i] if i + 1 < thetas.size else 0.0
        return float(max(left, right))
    if i == 0 or i == thetas.size:
        return float("inf")
    return float(thetas[i] - thetas[i - 1])


def _diffuse_angles(gamma: float, width: float, lo: float, hi: float,
                    wide_offset: float) -> list[float]:
    """Two receiver angles for the diffuse lobe at one angle of incidence, on a 5-deg grid,
    far from the specular lobe (``max(15, 5 w)`` deg from the mirror) and at least 10 deg
    from the source direction (``theta = gamma``): the one nearest the paper's
    ``mirror - wide_offset``, and the one nearest the normal at least 30 deg from it."""
    mirror = -gamma
    grid = np.arange(np.ceil(lo / 5.0) * 5.0, hi + _EPS, 5.0)
    keep = (np.abs(grid - mirror) >= max(15.0, 5.0 * width)) & (np.abs(grid - gamma) >= 10.0)
    cand = grid[keep]
    if cand.size < 2:
        raise IrreflectError(
            f"gamma {gamma:g}: the receiver range [{lo:g}, {hi:g}] leaves no room for two "
            "diffuse points away from the specular lobe and the source: widen the range"
        )
    first = mirror - wide_offset
    a = float(cand[np.argmin(np.abs(cand - first))])
    # the second: nearest the normal (the diffuse lobe's axis) at least 30 deg from the
    # first, ties away from the mirror
    apart = cand[np.abs(cand - a) >= 30.0 - _EPS]
    if not apart.size:
        apart = cand[cand != a]
    b = float(min(apart, key=lambda t: (abs(t), -abs(t - mirror))))
    return sorted([a, b])


def _nearest_free(available: dict, gamma: float, wanted: float, taken: list[float], lo: float,
                  hi: float) -> tuple[float, bool]:
    """The measured theta of ``gamma`` nearest to ``wanted`` that is not taken yet; of two
    as near, the lower (not the first in the pilot's rows: a shuffled pilot moved the mirror
    point of gamma 0 from theta -5.7 to +5.7)."""
    thetas = None
    for key, values in available.items():
        if abs(float(key) - gamma) <= 1e-6:
            thetas = np.asarray(values, float)
            break
    if thetas is None or not thetas.size:
        raise IrreflectError(
            f"the pilot scan has no measurement at gamma {gamma:g}: choose gammas it measured"
        )
    thetas = thetas[(thetas >= lo - _EPS) & (thetas <= hi + _EPS)]
    free = np.sort([t for t in thetas if all(abs(t - p) > _EPS for p in taken)])
    if not free.size:
        raise IrreflectError(
            f"the pilot scan has too few angles at gamma {gamma:g} for a 12-point protocol"
        )
    best = _clean(free[np.argmin(np.abs(free - wanted))])
    return best, abs(best - wanted) > _EPS
