"""Replays of measurement campaigns against a dense table used as the instrument.

The dense table answers every reading a strategy asks for: at its own settings (the
nearest measured setting within a tolerance), or interpolated along theta at a measured
angle of incidence; optionally with relative power noise and a receiver-angle error
(uniform, the power read where the receiver really stood), all seeded. Every strategy is
scored the same way: the model fitted to its readings only, judged by R^2 against *all*
points of the dense table, after each reading.

Strategies (:data:`STRATEGIES`):

``adaptive``
    :class:`~.core.Campaign`, one reading at a time (its opening design, then the adaptive
    rule); the verdict after each reading is recorded.
``paper``
    The paper's 12-point protocol (section 4.3) for the table's angles of incidence.
``glossy``
    The glossy-aware 12-point protocol designed from the dense table itself (a pilot scan
    of the same material: more than a new user has).
``random``
    Readings drawn at random from the instrument's settings (the median of three seeded
    draws at each N).
``hindsight``
    The best subsets of the dense table that ``irreflect select`` finds for each N, knowing
    every reading in advance: the bound no campaign reaches without hindsight.
"""

from __future__ import annotations

import dataclasses
import textwrap
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .. import metrics
from ..data import Measurements, as_measurements
from ..errors import FitError, FitWarning, IrreflectError, unknown_name
from ..fitting import FitResult, fit_averaged
from ..models import get_model
from ..models.aperture import check_resolution
from ..validation import check_int, check_number, check_search_budget, check_seed
from .core import Campaign
from .design import DEFAULT_RULE, DesignRule
from .instrument import Instrument

#: what the hindsight curve's note says when select's thorough fits are no bound
#: (:func:`replay_hindsight`)
NO_BOUND = "no bound here"
#: a hindsight curve whose best 12 points fall more than this below the paper's 12 points
#: (themselves a subset of 12) is no bound either: one rule for ``irreflect campaign``,
#: ``select``'s warning on its best 12 and experiments/bench_campaign.py
NO_BOUND_MARGIN = 0.01
STRATEGIES = ("adaptive", "paper", "glossy", "random", "hindsight")
#: The most readings a replayed campaign takes (``next`` reads at most as many).
MAX_REPLAY_READINGS = 2000
METHODS = ("nearest", "interpolate")
#: deg: readings of the dense table farther apart than this next to its peak are too coarse
#: to interpolate a specular lobe between (:meth:`DenseInstrument.coarse_peaks`)
COARSE_PEAK_DEG = 2.0
#: How close to the all-points fit's R^2 a strategy must come (and stay) to count.
TOLERANCE = 0.01


@dataclass(frozen=True)
class DenseInstrument:
    """A dense table that answers readings.

    dense : the table
    method : ``nearest`` (the table's own settings, a reading at most ``tolerance_deg``
        from one) or ``interpolate`` (every ``theta_step`` along theta at the table's
        angles of incidence, the power interpolated linearly)
    noise : relative power noise (1 sigma) added to every reading
    angle_error_deg : the receiver stands up to this far (uniform) from where it was set
    seed : seeds the noise and the angle errors
    """

    dense: Measurements
    method: str = "nearest"
    tolerance_deg: float = 0.5
    theta_step: float | None = None
    noise: float = 0.0
    angle_error_deg: float = 0.0
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "dense", as_measurements(self.dense))
        if self.method not in METHODS:
            raise unknown_name("instrument method", self.method, METHODS)
        check_number(self.tolerance_deg, "tolerance", low=0.0)
        check_number(self.noise, "noise", low=0.0)
        check_number(self.angle_error_deg, "angle error", low=0.0, high=10.0)
        check_seed(self.seed)
        if self.theta_step is not None:
            check_number(self.theta_step, "theta_step", low=0.0, low_open=True)
        if len(self.dense.gammas) < 1 or self.dense.n_points < 10:
            raise IrreflectError(
                f"{self.dense.name}: a dense table to replay campaigns on needs at least 10 "
                f"points; found {self.dense.n_points}")

    def instrument(self, **kwargs) -> Instrument:
        """The :class:`Instrument` whose settings this table can answer."""
        d = self.dense
        if self.method == "nearest":
            return Instrument.from_table(d.gamma_deg, d.theta_deg, **kwargs)
        step = self.theta_step or 1.0
        rows = []
        for g in d.gammas:
            th = d.theta_deg[d.gamma_deg == g]
            grid = np.arange(np.ceil(th.min() / step) * step, th.max() + 1e-9, step)
            rows.append(np.column_stack([np.full(grid.size, g), grid]))
        s = np.concatenate(rows)
        kwargs.setdefault("source_clearance", 0.0)
        kwargs.setdefault("min_separation", step / 2.0)
        return Instrument(gammas_deg=tuple(d.gammas), theta_min=float(s[:, 1].min()),
                          theta_max=float(s[:, 1].max()), theta_step=step, settings_deg=s,
                          **kwargs)

    def mirror_gaps(self) -> str:
        """A warning when the table has no reading near the specular peak (theta = -gamma,
        within the instrument's reach tolerance) at some angles of incidence: every
        strategy's fit extrapolates the peak there, and no R^2 scores it; empty otherwise.
        Judged on the table's own readings: with ``method="interpolate"`` a reading between
        them is the interpolation's, not a measurement of the peak."""
        tool = Instrument.from_table(self.dense.gamma_deg, self.dense.theta_deg)
        missed = tool.mirror_misses()
        if not missed:
            return ""
        return (f"the table has no reading within {tool.reach_tolerance:.3g} deg of the "
                f"specular peak (theta = -gamma) at gamma {', '.join(f'{g:g}' for g in missed)}"
                " deg: every strategy's fit extrapolates the peak there, and no R^2 below "
                "scores it (measure the mirror direction there to judge the lobe)")

    def _row(self, gamma: float, values=None) -> tuple[np.ndarray, np.ndarray]:
        """The table's readings at one angle of incidence, ``(theta, power)`` sorted by
        theta (empty where it has none); ``values``: another column than the power."""
        d = self.dense
        sel = np.abs(d.gamma_deg - gamma) < 1e-6
        order = np.argsort(d.theta_deg[sel])
        return d.theta_deg[sel][order], (d.power if values is None else values)[sel][order]

    def sigma_at(self, gamma_deg, theta_deg) -> np.ndarray | None:
        """The table's sigma at the given settings (degrees), read as its power is (the
        nearest reading, or interpolated along theta); None when the table has none. The
        readings of every strategy carry it, as the protocols' and the hindsight subsets'
        always did: a replay on a table with sigma weights every strategy's fit alike
        (before stop 42 the adaptive and the random readings were fitted unweighted)."""
        d = self.dense
        if d.sigma is None:
            return None
        out = []
        for gi, ti in zip(np.atleast_1d(np.asarray(gamma_deg, float)),
                          np.atleast_1d(np.asarray(theta_deg, float)), strict=True):
            th, sg = self._row(gi, d.sigma)
            out.append(sg[int(np.argmin(np.abs(th - ti)))] if self.method == "nearest"
                       else float(np.interp(ti, th, sg)))
        return np.asarray(out, float)

    def reading_sigma(self, gamma_deg, theta_deg, power) -> np.ndarray | None:
        """The sigma of readings of ``power`` at the given settings: the table's
        (:meth:`sigma_at`) and this instrument's relative noise added in quadrature; None
        when the table has no sigma."""
        sigma = self.sigma_at(gamma_deg, theta_deg)
        if sigma is None or not self.noise:
            return sigma
        return np.sqrt(sigma ** 2 + (self.noise * np.asarray(power, float)) ** 2)

    def coarse_peaks(self) -> str:
        """With ``method="interpolate"``: a warning when, at half or more of the angles of
        incidence, the table's own readings next to its brightest reading (the specular
        peak) lie more than :data:`COARSE_PEAK_DEG` and two receiver steps from it and
        below half its power (the lobe narrower than the table's step), so that the readings
        between them, the lobe's body and flanks, are invented by linear interpolation
        (a campaign that samples them learns the interpolation, not the material); empty
        otherwise."""
        if self.method != "interpolate":
            return ""
        d = self.dense
        step = self.theta_step or 1.0
        gaps, coarse = [], 0
        for g in d.gammas:
            th, pw = self._row(g)
            if th.size < 3:
                continue
            i = int(np.argmax(pw))
            near = [j for j in (i - 1, i + 1) if 0 <= j < th.size]
            gap = max(abs(th[j] - th[i]) for j in near)
            gaps.append(gap)
            # the lobe falls to less than half its peak within one of the table's steps:
            # narrower than the table resolves
            coarse += bool(gap > max(COARSE_PEAK_DEG, 2.0 * step)
                           and pw[i] > 2.0 * max(pw[j] for j in near))
        if not gaps or coarse * 2 < len(gaps):
            return ""
        return (f"{d.name}: its readings next to the specular peak are "
                f"{np.median(gaps):.3g} deg apart (median over its angles of incidence), the "
                f"lobe narrower than that at {coarse} of {len(gaps)}, and "
                f"--method interpolate reads every {step:g} deg between them by linear "
                "interpolation: the lobe a replayed campaign samples is invented, and its R^2 "
                "says little about the material; replay with --method nearest")

    def disturb(self, gamma_deg, theta_deg, power, rng: np.random.Generator) -> np.ndarray:
        """``power``, read at the given settings some other way (a protocol sampled from
        the table), with this instrument's errors: the receiver's angle error (the table
        interpolated along theta where the receiver stood) and the relative power noise.
        Unchanged when the instrument has neither."""
        out = np.array(power, float, copy=True)
        if self.angle_error_deg:
            for i, (gi, ti) in enumerate(zip(np.atleast_1d(gamma_deg),
                                             np.atleast_1d(theta_deg), strict=True)):
                stand = ti + rng.uniform(-1, 1) * self.angle_error_deg
                out[i] = float(np.interp(stand, *self._row(gi)))
        if self.noise:
            out = out * (1.0 + self.noise * rng.standard_normal(out.size))
        return out

    def read(self, gamma_deg, theta_deg, rng: np.random.Generator) -> np.ndarray:
        """Power at the given settings (degrees), with the instrument's errors."""
        d = self.dense
        g = np.atleast_1d(np.asarray(gamma_deg, float))
        t = np.atleast_1d(np.asarray(theta_deg, float))
        out = np.empty(g.size)
        for i, (gi, ti) in enumerate(zip(g, t, strict=True)):
            th, pw = self._row(gi)
            if not th.size:
                raise IrreflectError(f"{d.name} has no angle of incidence {gi:g} deg")
            gap = float(np.min(np.abs(th - ti)))
            if self.method == "nearest" and gap > self.tolerance_deg + 1e-9:
                raise IrreflectError(
                    f"({gi:g}, {ti:g}) is {gap:.3g} deg from the nearest reading of {d.name} "
                    f"at that angle of incidence, more than the tolerance "
                    f"{self.tolerance_deg:g} deg")
            if self.method == "nearest":
                out[i] = pw[int(np.argmin(np.abs(th - ti)))]
            else:
                out[i] = float(np.interp(ti, th, pw))
        return self.disturb(g, t, out, rng)


@dataclass
class StrategyCurve:
    """R^2 against all points of the dense table after each number of readings."""

    name: str
    r2: dict[int, float]
    points: pd.DataFrame  # the readings, in the order taken (gamma_deg, theta_deg, power)
    seconds: float = 0.0
    note: str = ""

    def reached(self, target: float) -> int | None:
        """The first N from which R^2 >= ``target`` holds at every later N (None: never)."""
        first = None
        for n in sorted(self.r2):
            if np.isfinite(self.r2[n]) and self.r2[n] >= target:
                first = n if first is None else first
            else:
                first = None
        return first

    def first(self, target: float) -> int | None:
        """The first N with R^2 >= ``target`` (it may fall again later)."""
        return next((n for n in sorted(self.r2) if self.r2[n] >= target), None)


@dataclass
class ReplayResult:
    """Every strategy's curve on one dense table, and the adaptive campaign's verdicts."""

    dataset: str
    n_points: int
    reference_r2: float
    curves: dict[str, StrategyCurve]
    verdicts: dict[int, object] = field(default_factory=dict)
    proposal_seconds: list[float] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def target(self) -> float:
        return self.reference_r2 - TOLERANCE

    @property
    def stop_n(self) -> int | None:
        """The first N at which the adaptive campaign's verdict said stop."""
        return next((n for n in sorted(self.verdicts) if self.verdicts[n].stop), None)

    def table(self) -> pd.DataFrame:
        """One row per N, one column per strategy: R^2 against all points."""
        ns = sorted({n for c in self.curves.values() for n in c.r2})
        data = {"N": ns}
        for name, c in self.curves.items():
            data[name] = [c.r2.get(n, np.nan) for n in ns]
        if self.verdicts:
            data["adaptive verdict"] = [
                ("stop" if self.verdicts[n].stop else "continue") if n in self.verdicts
                else "" for n in ns]
        return pd.DataFrame(data)

    def summary(self) -> pd.DataFrame:
        """One row per strategy: N reaching (and keeping) the all-points R^2 - 0.01, R^2
        at 12 and at the largest N."""
        rows = []
        for name, c in self.curves.items():
            ns = sorted(c.r2)
            rows.append({
                "strategy": name,
                "N reaching all-points R^2 - 0.01 (and keeping it)": c.reached(self.target),
                "R^2 at N = 12": c.r2.get(12, np.nan),
                "largest N": ns[-1] if ns else np.nan,
                "R^2 at the largest N": c.r2[ns[-1]] if ns else np.nan,
                "note": c.note,
            })
        return pd.DataFrame(rows)

    def to_dict(self) -> dict:
        """The replay as strict JSON (NaN and infinities as None)."""
        from .._jsonio import finite

        return finite({
            "dataset": self.dataset, "n_points": self.n_points,
            "reference_r2": self.reference_r2, "target": self.target,
            "stop_n": self.stop_n,
            "curves": {k: {"r2": {str(n): v for n, v in c.r2.items()},
                           "reached": c.reached(self.target), "seconds": c.seconds,
                           "note": c.note} for k, c in self.curves.items()},
            "verdicts": {str(n): v.to_dict() for n, v in self.verdicts.items()},
            "proposal_seconds": self.proposal_seconds,
            "settings": self.settings,
            "warnings": self.warnings,
        })


def _score(model, meas: Measurements, dense: Measurements, seed: int,
           resolution: float = 0.0) -> float:
    """R^2 against all of ``dense`` of the model fitted to ``meas`` (averaged over a
    receiver of ``resolution`` degrees, as the dense table's readings are)."""
    return _fit_and_score(model, meas, dense, seed, resolution)[0]


def _fit_and_score(model, meas: Measurements, dense: Measurements, seed: int,
                   resolution: float = 0.0) -> tuple[float, FitResult | None]:
    """:func:`_score` and the fit it scored (None when the fit failed)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            res = fit_averaged(meas, model, resolution, seed=seed)
    except (FitError, IrreflectError):
        return float("nan"), None
    with np.errstate(all="ignore"):
        r2 = metrics.r2(dense.power, res.predict(dense.gamma_deg, dense.theta_deg))
    return float(r2), res


def replay_adaptive(source: DenseInstrument, n_max: int = 25, *, model="two-lobe",
                    seed: int = 0, rule: DesignRule = DEFAULT_RULE, batch: int = 1,
                    instrument_options: dict | None = None, progress=None):
    """The adaptive campaign against the dense table, ``batch`` readings per proposal,
    up to ``n_max`` readings: (curve, verdicts per N, seconds per proposal, each with the
    verdict on the readings before it: the work ``irreflect next`` does per call)."""
    dense = source.dense
    rng = np.random.default_rng([check_seed(seed), 11])
    tool = source.instrument(**(instrument_options or {}))
    # a reading as negative as the dense table's own (which its check accepted as noise)
    # is noise, even among a campaign's first few small readings
    floor = max(0.0, -float(np.min(dense.power)))
    campaign = Campaign(tool, model=model, seed=seed, rule=rule, name=dense.name,
                        noise_floor=floor)
    r2, verdicts, times = {}, {}, []
    t0 = time.perf_counter()
    judged = 0.0  # the verdict's time, counted with the proposal after it (they share work)
    while campaign.n_measured < n_max:
        if not campaign.n_free:
            break
        start = time.perf_counter()
        proposal = campaign.propose(min(batch, n_max - campaign.n_measured))
        times.append(time.perf_counter() - start + judged)
        if not len(proposal):
            break
        power = source.read(proposal["gamma_deg"], proposal["theta_deg"], rng)
        rows = proposal[["gamma_deg", "theta_deg"]].assign(power=power)
        sigma = source.reading_sigma(proposal["gamma_deg"], proposal["theta_deg"], power)
        campaign.add(rows if sigma is None else rows.assign(sigma=sigma))
        n = campaign.n_measured
        start = time.perf_counter()
        v = campaign.verdict()
        judged = time.perf_counter() - start
        verdicts[n] = v
        if campaign.fit is not None:
            r2[n] = campaign.r2_against(dense)
        if progress:
            progress(n)
    meas = campaign.measurements
    points = meas.to_frame() if meas is not None else pd.DataFrame()
    return (StrategyCurve("adaptive", r2, points, time.perf_counter() - t0), verdicts, times)


def replay_protocol(source: DenseInstrument, kind: str, *, model="two-lobe",
                    seed: int = 0, resolution: float = 0.0) -> StrategyCurve:
    """The paper's (``kind="paper"``) or the glossy-aware (``"glossy"``) 12-point protocol,
    its power read from the dense table (interpolated along theta where the table did not
    measure its angles) with the instrument's noise and angle error, as the adaptive
    campaign's readings are: R^2 at N = 12."""
    from ..protocol.evaluate import glossy_protocol_for, paper_protocol_for, sample_protocol

    dense = source.dense
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            proto = (paper_protocol_for(dense) if kind == "paper"
                     else glossy_protocol_for(dense, seed=seed))
        meas, frame = sample_protocol(proto, dense, tolerance_deg=max(5.0,
                                                                    source.tolerance_deg))
    except (IrreflectError, FitError) as exc:
        return StrategyCurve(kind, {}, pd.DataFrame(), time.perf_counter() - t0,
                             note=f"not available: {textwrap.shorten(str(exc), 400, placeholder=' ...')}")
    if source.noise or source.angle_error_deg:  # the instrument's errors, as every reading
        rng = np.random.default_rng([check_seed(seed), 37, ("paper", "glossy").index(kind)])
        power = source.disturb(meas.gamma_deg, meas.theta_deg, meas.power, rng)
        sigma = (None if meas.sigma is None else
                 np.sqrt(meas.sigma ** 2 + (source.noise * power) ** 2))
        meas = Measurements(gamma_deg=meas.gamma_deg, theta_deg=meas.theta_deg,
                            power=power, sigma=sigma, name=meas.name)
    r2, res = _fit_and_score(model, meas, dense, seed, resolution)
    gammas = "/".join(f"{g:g}" for g in proto.settings.get("gammas_deg", proto.gammas))
    note = f"gammas {gammas} deg"
    moved = int(np.sum(frame["source"] == "interpolated")) if "source" in frame else 0
    if moved:  # as evaluate-protocol reads them; select's Method 12 snaps them instead
        note += (f"; {moved} of {len(frame)} readings interpolated along theta (select's "
                 "Method 12 snaps them to measured points)")
    if res is not None and (res.ill_determined or res.at_bound):
        # a fit these points do not pin down: small changes of its readings move it far
        flags = [f"{len(res.ill_determined)} of {len(res.param_names)} coefficients "
                 "ill-determined"] if res.ill_determined else []
        flags += [f"at a bound: {', '.join(res.at_bound)}"] if res.at_bound else []
        note += f"; its fit: {'; '.join(flags)}"
    return StrategyCurve(kind, {meas.n_points: r2}, meas.to_frame(),
                         time.perf_counter() - t0, note=note)


def replay_random(source: DenseInstrument, n_max: int = 25, *, model="two-lobe", seed: int = 0,
                  n_draws: int = 3, resolution: float = 0.0) -> StrategyCurve:
    """Readings at random settings of the instrument, one at a time; the median R^2 over
    ``n_draws`` seeded draws at each N."""
    dense = source.dense
    model_obj = get_model(model)
    tool = source.instrument()
    settings = tool.settings()
    t0 = time.perf_counter()
    per_n: dict[int, list[float]] = {}
    first = None
    for draw in range(n_draws):
        rng = np.random.default_rng([check_seed(seed), 29, draw])
        order = rng.permutation(len(settings))[:n_max]
        s = settings[order]
        power = source.read(s[:, 0], s[:, 1], rng)
        sigma = source.reading_sigma(s[:, 0], s[:, 1], power)
        if first is None:
            first = pd.DataFrame({"gamma_deg": s[:, 0], "theta_deg": s[:, 1], "power": power})
        for n in range(model_obj.n_params + 1, len(order) + 1):
            meas = Measurements(gamma_deg=s[:n, 0], theta_deg=s[:n, 1], power=power[:n],
                                sigma=None if sigma is None else sigma[:n], name=dense.name)
            per_n.setdefault(n, []).append(_score(model_obj, meas, dense, seed, resolution))
    r2 = {n: float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")
          for n, v in per_n.items()}
    return StrategyCurve("random", r2, first if first is not None else pd.DataFrame(),
                         time.perf_counter() - t0, note=f"median of {n_draws} seeded draws")


def replay_hindsight(source: DenseInstrument, n_max: int = 25, *, model="two-lobe",
                     seed: int = 0, generations: int = 100, pop_size: int = 100,
                     progress: bool = False) -> StrategyCurve:
    """``select``'s best subsets of the dense table for each N up to ``n_max`` (every
    reading known in advance): R^2 against all points; N without a subset of its own take
    the best of fewer points (a subset of fewer readings is at hand)."""
    from ..selection import run_selection

    dense = source.dense
    t0 = time.perf_counter()
    n_top = min(n_max, dense.n_points)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        sel = run_selection(dense, model, max_points=n_top, generations=generations,
                            pop_size=pop_size, seed=seed, enough=False, progress=progress)
    front = dict(zip(sel.front["n_points"].astype(int), sel.front["r2"].astype(float),
                     strict=True))
    r2, best = {}, -np.inf
    for n in range(min(front) if front else n_top + 1, n_top + 1):
        best = max(best, front.get(n, -np.inf))
        r2[n] = float(best)
    mask = sel.best_mask(12) if sel.best_mask(12) is not None else sel.best_mask(sel.knee_n)
    pts = dense.subset(mask).to_frame() if mask is not None else pd.DataFrame()
    note = f"select's best subsets, nsga2 {generations} generations x {pop_size}"
    quick = sel.search_best.get(12)
    if quick is not None and 12 in r2 and 1.0 - quick[0] > r2[12] + 0.05:
        # select's thorough fits of its subsets settled where they have no point (a noisy
        # matte table: -235.6, while the search's own fits of the same 12 gave 0.9154)
        note += (f"; {NO_BOUND}: the thorough fit of its best 12 points gives R^2 "
                 f"{r2[12]:.4g}, the search's own fit of them {1.0 - quick[0]:.4g} (12 points "
                 "leave the model's optimum free where they have no point)")
    return StrategyCurve("hindsight", r2, pts, time.perf_counter() - t0, note=note)


def _below_paper(curves: dict) -> None:
    """Marks the hindsight curve as no bound when its best 12 points fall more than
    :data:`NO_BOUND_MARGIN` below the paper's 12 points (the benchmark's rule; the note of
    :func:`replay_hindsight` catches the thorough fit's fall only beyond 0.05 of the search's
    own fit)."""
    hind, paper = curves.get("hindsight"), curves.get("paper")
    if hind is None or paper is None or NO_BOUND in hind.note:
        return
    h12, p12 = hind.r2.get(12), paper.r2.get(12)
    if h12 is not None and p12 is not None and h12 < p12 - NO_BOUND_MARGIN:
        hind.note += (f"; {NO_BOUND}: its best 12 points give R^2 {h12:.4g}, more than "
                      f"{NO_BOUND_MARGIN:g} below the paper's 12 points' {p12:.4g}")


def _reference_misfit(reference: FitResult, dense: Measurements) -> str:
    """The warning when the all-points fit, the campaigns' target, explains its table
    poorly: a target of R^2 0.26 is met by almost any campaign, and says nothing of it."""
    r2 = float(reference.r2)
    if not (np.isfinite(r2) and r2 < metrics.MISFIT_R2):
        return ""
    text = (f"the all-points fit explains the table only to R^2 {r2:.4g}: the model "
            "misfits this material, and coming within 0.01 of it says little of a campaign "
            "(irreflect diagnose names what the model lacks)")
    if dense.sigma is not None:
        text += (f"; its fit is weighted by the sigma column (reduced chi^2 "
                 f"{reference.chi2_reduced:.4g}) while R^2 weighs every point alike: "
                 "without the column the fits are scored in power units")
    return text


def _reference_unseen_lobe(reference: FitResult) -> str:
    """The warning when the all-points fit's specular lobe falls between the table's
    receiver angles at every angle of incidence where it matters (no reading within its half
    width at any): its share then only scales the diffuse lobe with gamma, and the fit
    that sets the target is one the fit's own verdict calls NOT TRUSTWORTHY. Seen on matte
    Oren-Nayar tables on the Cornell grid (all points R^2 0.966 with a lobe 0.46-0.0008 deg
    wide, the campaign 0.950); on none of the 11 real sets. Empty otherwise."""
    from ..verdict import fit_verdict

    try:
        verdict = fit_verdict(reference)
    except (ValueError, FloatingPointError, IrreflectError):
        return ""
    angles = [a for a in verdict.angles if a.lobe_matters]
    if len(angles) < 2 or any(a.lobe_points_1hw > 0 or a.lobe_resolved for a in angles):
        return ""
    widths = [a.lobe_half_width_deg for a in angles]
    return (f"the all-points fit, which sets the target, puts a specular lobe "
            f"{min(widths):.2g}-{max(widths):.2g} deg wide (half width) where no reading of "
            f"the table falls, at each of its {len(angles)} angles of incidence: the lobe is "
            "not measured, its share only scales the diffuse lobe with gamma, and that fit is "
            "NOT TRUSTWORTHY ('irreflect fit' gives its verdict): a target of its R^2 "
            f"({reference.r2:.4g}) says little of a campaign")


def _interpolation_limit(source: DenseInstrument, reference: FitResult, model, seed: int,
                         resolution: float = 0.0) -> str:
    """With ``method="interpolate"``: the warning when the model fitted to every setting the
    instrument answers (the interpolated table itself, without noise) scores below the
    target against the table's own points: a strategy that reads between the table's
    receivers may then fall short of it for that reason. On Cornell Krylon, every 2 deg, that fit
    scores R^2 0.9706 against the target 0.9716 (all points 0.9816), and the adaptive
    campaign, which reads the mirror directions between the 8-deg receivers, never held the
    target while the paper's protocol did; with ``nearest`` it holds from 11. Empty
    otherwise."""
    if source.method != "interpolate":
        return ""
    quiet = dataclasses.replace(source, noise=0.0, angle_error_deg=0.0)
    s = quiet.instrument().settings()
    table = Measurements(gamma_deg=s[:, 0], theta_deg=s[:, 1],
                         power=quiet.read(s[:, 0], s[:, 1], np.random.default_rng(seed)),
                         name=source.dense.name)
    r2, _ = _fit_and_score(model, table, source.dense, seed, resolution)
    target = float(reference.r2) - TOLERANCE
    if not (np.isfinite(r2) and r2 < target):
        return ""
    return (f"--method interpolate: the model fitted to all {len(s)} settings the "
            f"interpolated table answers scores R^2 {r2:.4f} against the table's own "
            f"points, below the target {target:.4f}: a strategy that reads between the "
            "table's receivers learns the interpolation, not the material: where a strategy "
            "falls short of the target below, the interpolation may be why, not its design "
            "(replay with --method nearest)")


def replay(dense, strategies=STRATEGIES, *, n_max: int = 25, model="two-lobe", seed: int = 0,
           method: str = "nearest", tolerance_deg: float = 0.5, theta_step=None,
           noise: float = 0.0, angle_error_deg: float = 0.0, generations: int = 100,
           rule: DesignRule = DEFAULT_RULE, reference: FitResult | None = None,
           progress=None, resolution: float = 0.0) -> ReplayResult:
    """Replay every strategy of ``strategies`` against ``dense`` (a path, DataFrame or
    Measurements) used as the instrument; see the module docstring.

    n_max : readings of the adaptive campaign, random readings and hindsight subsets
    method, tolerance_deg, theta_step, noise, angle_error_deg : see :class:`DenseInstrument`
    generations : NSGA-II generations of the hindsight bound (population 100)
    reference : the model's fit on all points of ``dense`` (fitted when not given, and
        refitted averaged over the receiver when ``resolution`` is given)
    progress : callable(str), told what runs
    resolution : deg, the full width of receiver angle each reading of ``dense`` averages
        over (0: a point receiver): the adaptive campaign's instrument has it, and the
        protocols', random readings' and the reference fit are the model averaged over it
        (:func:`irreflect.fitting.fit_averaged`), as ``irreflect fit --resolution`` fits;
        the hindsight subsets are selected and scored as points (``select`` has no
        resolution), which their note says
    """
    dense = as_measurements(dense)
    n_max = check_int(n_max, "n_max", 9)
    if n_max > MAX_REPLAY_READINGS:
        raise IrreflectError(f"n_max (--n-max) {n_max}: a replayed campaign takes at most "
                             f"{MAX_REPLAY_READINGS} readings (one fit each): pass --n-max "
                             f"{MAX_REPLAY_READINGS} or less")
    for s in strategies:
        if s not in STRATEGIES:
            raise unknown_name("campaign strategy", s, STRATEGIES)
    if "hindsight" in strategies:  # before any work: the hindsight bound is a selection
        check_search_budget(100, check_int(generations, "generations", 1), dense.n_points,
                            pop_option="population", gen_option="--generations")
    model_obj = get_model(model)
    resolution = check_resolution(resolution)
    source = DenseInstrument(dense, method=method, tolerance_deg=tolerance_deg,
                             theta_step=theta_step, noise=noise,
                             angle_error_deg=angle_error_deg, seed=seed)
    if resolution:  # an instrument that cannot take readings this wide: refused before a fit
        source.instrument(resolution=resolution)
    if reference is None or reference.model != model_obj.name or resolution:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            reference = fit_averaged(dense, model_obj, resolution, seed=seed)
    say = progress or (lambda text: None)
    curves, verdicts, times = {}, {}, []
    for s in strategies:
        say(f"{dense.name}: {s}")
        if s == "adaptive":
            curves[s], verdicts, times = replay_adaptive(
                source, n_max, model=model_obj, seed=seed, rule=rule,
                instrument_options={"resolution": resolution} if resolution else None)
        elif s in ("paper", "glossy"):
            curves[s] = replay_protocol(source, s, model=model_obj, seed=seed,
                                        resolution=resolution)
        elif s == "random":
            curves[s] = replay_random(source, n_max, model=model_obj, seed=seed,
                                      resolution=resolution)
        else:
            curves[s] = replay_hindsight(source, n_max, model=model_obj, seed=seed,
                                         generations=generations)
            if resolution:
                curves[s].note += (f"; selected and scored as points (select has no "
                                   f"resolution), not averaged over {resolution:g} deg")
    _below_paper(curves)
    return ReplayResult(
        dataset=dense.name, n_points=dense.n_points, reference_r2=float(reference.r2),
        curves=curves, verdicts=verdicts, proposal_seconds=times,
        warnings=[w for w in (source.coarse_peaks(), source.mirror_gaps(),
                              _interpolation_limit(source, reference, model_obj, seed,
                                                   resolution),
                              _reference_misfit(reference, dense),
                              _reference_unseen_lobe(reference)) if w],
        settings={"n_max": n_max, "model": model_obj.name, "seed": seed, "method": method,
                  "tolerance_deg": tolerance_deg, "theta_step": theta_step, "noise": noise,
                  "angle_error_deg": angle_error_deg, "generations": generations,
                  "resolution_deg": resolution})
