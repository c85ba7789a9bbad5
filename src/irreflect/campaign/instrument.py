"""What a goniometer can do: the settings a campaign may propose.

An :class:`Instrument` lists the angles of incidence the source arm can be set to, the
receiver's range, step and angular resolution, the smallest separation between two
receiver angles that count as different readings, how close the receiver may come to the
source direction, and the cost of changing the angle of incidence (the slow step of most
goniometers). Its
:meth:`~Instrument.settings` are every (gamma, theta) reading it can take; they are both the
candidates of a proposal and, by default, the range over which the predicted curve must be
right (the "range the user cares about").

Angles in degrees, the paper's convention: gamma <= 0 on the source side, theta signed, the
mirror direction at theta = -gamma. Angles of incidence given as magnitudes (all >= 0) are
read as gamma = -|gamma|, as the tables are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import IrreflectError
from ..models.aperture import unresolved as unresolved_lobe
from ..validation import check_number, check_real_array

#: Largest number of settings a campaign scores at once (the range and the candidates are
#: thinned to this many, keeping the settings near a mirror direction first): the
#: proposal's matrices grow with its square (900: about 0.1 s a proposal).
MAX_SETTINGS = 900
#: An instrument lists at most this many (gamma, theta) settings (a --theta-step of 1e-9 deg
#: would list 1.6e11 and exhaust memory before the first proposal).
MAX_INSTRUMENT_SETTINGS = 1_000_000

#: deg: a setting this close to the mirror direction reads the specular peak; farther (a
#: coarse receiver step), the opening calls it the setting nearest the mirror, and ``next``
#: warns that a lobe narrower than the offset goes unmeasured.
MIRROR_NEAR_DEG = 2.0


@dataclass(frozen=True)
class Instrument:
    """A goniometer's limits, in degrees.

    Parameters
    ----------
    gammas_deg : sequence of float
        The angles of incidence the source arm can be set to (<= 0, or magnitudes).
    theta_min, theta_max : float
        The receiver's range.
    theta_step : float
        The receiver's step: it stands at ``theta_min + k * theta_step``.
    min_separation : float
        Two readings at one angle of incidence closer than this are the same reading
        (default: half the step, or half the resolution when that is larger).
    source_clearance : float
        The receiver cannot stand within this many degrees of the source direction
        ``theta = gamma`` (the arms collide; 0: no limit).
    gamma_change_cost : float
        The cost of setting a new angle of incidence, in readings (0: free). A proposal's
        expected gain is divided by ``1 + cost`` when it needs a new setting.
    max_gamma_settings : int, optional
        At most this many distinct angles of incidence over the whole campaign.
    resolution : float
        The receiver's angular resolution: the full width of the receiver angles a reading
        averages over (its acceptance; 0: a point receiver). The campaign fits its readings
        as the model averaged over it (:func:`irreflect.models.aperture.with_aperture`; the
        coefficients are the material's), readings closer than half of it are not proposed,
        the opening's lobe probes stand at least this far from the mirror, and a specular
        lobe narrower than it is warned of (:meth:`unresolved`).
    settings_deg : (n, 2) array, optional
        An explicit list of (gamma, theta) settings (a dense table used as the
        instrument); then ``theta_step`` only sets the default separation.
    """

    gammas_deg: tuple[float, ...]
    theta_min: float = -85.0
    theta_max: float = 85.0
    theta_step: float = 1.0
    min_separation: float | None = None
    source_clearance: float = 5.0
    gamma_change_cost: float = 0.0
    max_gamma_settings: int | None = None
    resolution: float = 0.0
    settings_deg: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.gammas_deg is None:
            raise IrreflectError("gammas_deg must list the angles of incidence the source arm "
                                 "can be set to, in degrees; found None: pass e.g. "
                                 "gammas_deg=(-10, -30, -50) (--gammas G [G ...])")
        gammas = check_real_array(self.gammas_deg, "gammas_deg (the angles of incidence)",
                                  ndim=None, source="the instrument").ravel()
        if gammas.size == 0:
            raise IrreflectError("the instrument needs at least one angle of incidence "
                                 "(--gammas G [G ...]); found none")
        if not np.all(np.isfinite(gammas)) or np.any(np.abs(gammas) >= 90):
            bad = gammas[~np.isfinite(gammas) | (np.abs(gammas) >= 90)][0]
            raise IrreflectError(f"angles of incidence must lie strictly between -90 and 90 "
                                 f"degrees; found {bad:g}")
        if np.any(gammas > 0) and np.any(gammas < 0):
            raise IrreflectError(
                "the angles of incidence mix signs, which is ambiguous: give them all <= 0 "
                "(the paper's convention) or all as magnitudes >= 0")
        rounded = np.round(-np.abs(gammas), 9) + 0.0
        values, counts = np.unique(rounded, return_counts=True)
        if np.any(counts > 1):
            twice = values[counts > 1][0]
            raise IrreflectError(
                f"the angles of incidence (gammas_deg, --gammas) list {twice:g} deg "
                f"{int(counts[counts > 1][0])} times; found "
                f"{', '.join(f'{g:g}' for g in gammas)}: give each angle once")
        gammas = values
        gammas = gammas[np.argsort(np.abs(gammas), kind="stable")]
        object.__setattr__(self, "gammas_deg", tuple(float(g) for g in gammas))
        lo = check_number(self.theta_min, "theta_min", low=-90.0, high=90.0, low_open=True,
                          high_open=True)
        hi = check_number(self.theta_max, "theta_max", low=-90.0, high=90.0, low_open=True,
                          high_open=True)
        if not lo < hi:
            raise IrreflectError(f"the receiver range needs theta_min < theta_max; found "
                                 f"{lo:g} and {hi:g}: "
                                 + ("swap them" if lo > hi else "give a range of angles"))
        step = check_number(self.theta_step, "theta_step", low=0.0, low_open=True)
        if step > hi - lo:
            raise IrreflectError(f"the receiver step {step:g} deg is wider than its range "
                                 f"[{lo:g}, {hi:g}]: give a smaller --theta-step")
        n_gammas = max(len(tuple(self.gammas_deg)), 1)
        per_gamma = math.floor((hi - lo) / step + 1e-9) + 1
        if self.settings_deg is None and per_gamma * n_gammas > MAX_INSTRUMENT_SETTINGS:
            smallest = (hi - lo) / max(MAX_INSTRUMENT_SETTINGS // n_gammas - 1, 1)
            raise IrreflectError(
                f"theta_step (--theta-step) {step:g} deg: {per_gamma:,} receiver angles x "
                f"{n_gammas} angle(s) of incidence is more settings than an instrument may "
                f"list ({MAX_INSTRUMENT_SETTINGS:,}): pass --theta-step "
                f"{math.ceil(smallest * 1000) / 1000:g} or more")
        resolution = check_number(self.resolution, "resolution (--resolution)", low=0.0,
                                  high=90.0)
        sep = max(step, resolution) / 2.0 if self.min_separation is None else check_number(
            self.min_separation, "min_separation", low=0.0)
        if sep > hi - lo and hi > lo:
            raise IrreflectError(
                f"min_separation (--min-separation) {sep:g} deg is wider than the receiver's "
                f"range ({lo:g}..{hi:g} deg, {hi - lo:g} deg): one reading would rule out "
                f"every other setting at its angle of incidence; give at most {hi - lo:g}")
        clearance = check_number(self.source_clearance, "source_clearance", low=0.0,
                                 high=90.0)
        cost = check_number(self.gamma_change_cost, "gamma_change_cost", low=0.0)
        if self.max_gamma_settings is not None and (
                isinstance(self.max_gamma_settings, bool)
                or int(self.max_gamma_settings) != self.max_gamma_settings
                or self.max_gamma_settings < 1):
            raise IrreflectError(f"max_gamma_settings must be an integer >= 1; found "
                                 f"{self.max_gamma_settings!r}")
        for name, value in (("theta_min", lo), ("theta_max", hi), ("theta_step", step),
                            ("min_separation", sep), ("source_clearance", clearance),
                            ("gamma_change_cost", cost), ("resolution", resolution)):
            object.__setattr__(self, name, float(value))
        if self.settings_deg is not None:
            object.__setattr__(self, "settings_deg", _checked_settings(self.settings_deg))
            _check_settings_gammas(self.settings_deg, self.gammas)
        if not len(self.settings()):
            raise IrreflectError(
                f"the instrument can take no reading: every receiver angle in [{lo:g}, "
                f"{hi:g}] lies within {clearance:g} deg of the source direction at the given "
                "angles of incidence: widen the range or lower --source-clearance")

    @classmethod
    def from_table(cls, gamma_deg, theta_deg, **kwargs) -> Instrument:
        """The instrument that can take exactly the readings of a (dense) table."""
        g = check_real_array(gamma_deg, "gamma_deg", ndim=None, finite=False).ravel()
        t = check_real_array(theta_deg, "theta_deg", ndim=None, finite=False).ravel()
        if not g.size or g.size != t.size:
            raise IrreflectError(
                f"an instrument from a table needs its readings' gamma and theta, one of each "
                f"per reading; found {g.size} gamma(s) and {t.size} theta(s)")
        g = -np.abs(g) if np.all(g >= 0) else g  # magnitudes, as gammas_deg
        diffs = np.concatenate([np.diff(np.unique(t[g == x])) for x in np.unique(g)])
        step = float(np.min(diffs)) if diffs.size else 1.0
        kwargs.setdefault("source_clearance", 0.0)
        kwargs.setdefault("theta_step", step)
        kwargs.setdefault("min_separation", 1e-6)
        return cls(gammas_deg=tuple(np.unique(g)), theta_min=float(t.min()),
                   theta_max=float(t.max()), settings_deg=np.column_stack([g, t]), **kwargs)

    def capacity(self) -> int:
        """The most distinct readings the instrument can take: per angle of incidence, the
        receiver settings at least ``min_separation`` apart (greedily, along theta), summed
        over the ``max_gamma_settings`` angles that hold the most."""
        s = self.settings()
        counts = []
        for g in np.unique(s[:, 0]):
            ts = np.sort(s[s[:, 0] == g, 1])
            if np.all(np.diff(ts) >= self.min_separation - 1e-9):
                counts.append(ts.size)  # every setting apart (the usual case: no loop)
                continue
            last, k = -np.inf, 0
            for t in ts:
                if t - last >= self.min_separation - 1e-9:
                    last, k = t, k + 1
            counts.append(k)
        counts.sort(reverse=True)
        if self.max_gamma_settings is not None:
            counts = counts[:int(self.max_gamma_settings)]
        return int(sum(counts))

    @property
    def gammas(self) -> np.ndarray:
        """The angles of incidence, by increasing magnitude."""
        return np.asarray(self.gammas_deg, float)

    def snap_gammas(self, readings):
        """``readings`` (:class:`~irreflect.data.Measurements` or a DataFrame with
        ``gamma_deg``) with each angle of incidence
        within :data:`irreflect.data.GAMMA_JITTER_SPAN` of one the instrument lists read at
        that one, and a note naming them (None when none moved): a goniometer reporting its
        encoder (-69.96 for -70) had its readings fitted as at angles the instrument does
        not list, and the verdict's range left them out."""
        from dataclasses import replace

        from ..data import GAMMA_JITTER_SPAN

        if readings is None or not len(readings.gamma_deg) or not len(self.gammas):
            return readings, None
        g = np.asarray(readings.gamma_deg, float)
        nearest = self.gammas[np.argmin(np.abs(g[:, None] - self.gammas[None, :]), axis=1)]
        move = (np.abs(g - nearest) <= GAMMA_JITTER_SPAN) & (g != nearest)
        if not move.any():
            return readings, None
        pairs = sorted({(float(a), float(b)) for a, b in zip(g[move], nearest[move],
                                                            strict=True)}, key=lambda p: abs(p[1]))
        note = (f"{int(move.sum())} reading(s) within {GAMMA_JITTER_SPAN:g} deg of an angle of "
                "incidence of the instrument are taken at it (gamma "
                + ", ".join(f"{a:.4g} -> {b:g}" for a, b in pairs[:8])
                + (", ..." if len(pairs) > 8 else "") + " deg): jitter of the goniometer's "
                "reading; list those angles in the instrument's (gammas_deg, --gammas) to keep "
                "them apart")
        if not hasattr(readings, "n_points"):  # a DataFrame (Campaign.add)
            return readings.assign(gamma_deg=np.where(move, nearest, g)), note
        return replace(readings, gamma_deg=np.where(move, nearest, g)), note

    def reading_notes(self, gamma_deg, theta_deg) -> list[str]:
        """Notes on readings that stand where the instrument does not reach: at angles of
        incidence it does not list or beyond its receiver range (they are fitted, but the
        proposals and the verdict's range are the instrument's), or at more angles of
        incidence than ``max_gamma_settings`` allows. ``Campaign.add`` warns them
        (:class:`irreflect.data.DataNotice`); ``irreflect next`` prints them."""
        g, t = np.asarray(gamma_deg, float), np.asarray(theta_deg, float)
        listed = {round(float(x), 6) for x in self.gammas}
        other = sorted({round(float(x), 6) for x in g} - listed, key=abs)
        out = []
        if other:
            out.append(f"readings at gamma {', '.join(f'{x:g}' for x in other)} deg, which "
                       "the instrument does not list (gammas_deg, --gammas): they are fitted, "
                       "but the proposals and the verdict's predicted R^2 cover only the "
                       "listed angles; add them to its angles of incidence to include them")
        beyond = int(np.sum((t < self.theta_min - 1e-6) | (t > self.theta_max + 1e-6)))
        if beyond:
            out.append(f"{beyond} reading(s) at theta beyond the receiver range "
                       f"{self.theta_min:g}..{self.theta_max:g} deg: they are fitted, but the "
                       "verdict's predicted R^2 covers only the range (theta_min/theta_max, "
                       "--theta-min/--theta-max)")
        close = _close_pairs(g, t, self.min_separation)
        if close:
            ga, ta, tb = close[0]
            more = f" (and {len(close) - 1} more)" if len(close) > 1 else ""
            out.append(f"{len(close)} pair(s) of readings closer than the instrument's "
                       f"min_separation (--min-separation) {self.min_separation:g} deg: at "
                       f"gamma {ga:g}, theta {ta:g} and {tb:g}{more}; they are fitted, but "
                       "the instrument would not have proposed them so close; average them "
                       "into one row if they repeat one setting")
        used = len({round(float(x), 6) for x in g})
        limit = self.max_gamma_settings
        if limit and used > limit:
            out.append(f"the readings already use {used} angles of incidence, more than "
                       f"max_gamma_settings (--gamma-settings) {limit}: the proposals stay "
                       "at the measured ones")
        return out

    def settings(self) -> np.ndarray:
        """Every (gamma, theta) reading the instrument can take, ``(n, 2)`` degrees, sorted
        by |gamma| then theta."""
        if self.settings_deg is not None:
            s = self.settings_deg
            keep = np.abs(s[:, 1] - s[:, 0]) >= self.source_clearance - 1e-9
            s = s[keep]
        else:
            count = int(np.floor((self.theta_max - self.theta_min) / self.theta_step + 1e-9))
            thetas = np.round(self.theta_min + self.theta_step * np.arange(count + 1), 9)
            rows = []
            for g in self.gammas:
                t = thetas[np.abs(thetas - g) >= self.source_clearance - 1e-9]
                rows.append(np.column_stack([np.full(t.size, g), t]))
            s = np.concatenate(rows) if rows else np.zeros((0, 2))
        order = np.lexsort((s[:, 1], np.abs(s[:, 0])))
        return s[order] + 0.0

    @property
    def reach_tolerance(self) -> float:
        """deg: a setting this close to a direction measures it (two receiver steps, at
        least 2 deg)."""
        return max(2.0 * self.theta_step, 2.0)

    def _mirror_distances(self) -> dict[float, float]:
        """deg: per angle of incidence, how far its nearest setting stands from the mirror
        direction (theta = -gamma; infinite without a setting)."""
        s = self.settings()
        out = {}
        for g in self.gammas:
            t = s[np.abs(s[:, 0] - g) < 1e-6, 1]
            out[float(g)] = float(np.min(np.abs(t + g))) if t.size else math.inf
        return out

    def mirror_misses(self) -> tuple[float, ...]:
        """The angles of incidence whose mirror direction (theta = -gamma, the specular
        peak) no setting reaches within :attr:`reach_tolerance`: the specular lobe's peak
        there can only be extrapolated."""
        return tuple(g for g, d in self._mirror_distances().items()
                     if d > self.reach_tolerance)

    def mirror_blocked(self, gamma: float) -> str | None:
        """Why no receiver setting can stand at the mirror direction (theta = -gamma) of
        ``gamma``, whatever the step: ``"range"`` (beyond the receiver's range),
        ``"source"`` (within the source clearance: at normal incidence the mirror is the
        source direction), or None."""
        mirror = -float(gamma)
        if not self.theta_min - 1e-9 <= mirror <= self.theta_max + 1e-9:
            return "range"
        if abs(mirror - float(gamma)) < self.source_clearance - 1e-9:
            return "source"
        return None

    def mirror_offsets(self) -> dict[float, float]:
        """deg: per angle of incidence whose mirror direction the instrument reaches
        (:meth:`mirror_misses`), how far its nearest setting stands from it."""
        return {g: d for g, d in self._mirror_distances().items()
                if d <= self.reach_tolerance}

    def unresolved(self, half_widths: dict[float, float]) -> str:
        """:func:`irreflect.models.aperture.unresolved` at this receiver's resolution."""
        return unresolved_lobe(half_widths, self.resolution)

    def describe(self) -> str:
        """One line: what the instrument can do."""
        g = ", ".join(f"{x:g}" for x in self.gammas)
        parts = [f"angles of incidence {g} deg",
                 f"receiver {self.theta_min:g}..{self.theta_max:g} deg"
                 + ("" if self.settings_deg is not None else f" every {self.theta_step:g} deg")]
        if self.resolution:
            parts.append(f"resolution {self.resolution:g} deg")
        if self.source_clearance:
            parts.append(f"at least {self.source_clearance:g} deg from the source")
        if self.max_gamma_settings:
            parts.append(f"at most {self.max_gamma_settings} angle-of-incidence settings")
        if self.gamma_change_cost:
            parts.append(f"a new angle of incidence costs {self.gamma_change_cost:g} readings")
        return "; ".join(parts)


def thin_settings(settings: np.ndarray, limit: int = MAX_SETTINGS, keep=None) -> np.ndarray:
    """Indices of at most ``limit`` of ``settings``: all of ``keep`` (a boolean mask, e.g.
    the settings near a mirror direction; an even spread of them when they are more than
    half the limit: the first half of them had left the largest angles of incidence
    without their mirror settings) and an even spread of the others."""
    n = len(settings)
    if n <= limit:
        return np.arange(n)
    keep = np.zeros(n, bool) if keep is None else np.asarray(keep, bool)
    kept = np.flatnonzero(keep)
    if kept.size > limit // 2:  # an even spread of them too, over every angle of incidence
        kept = kept[np.unique(np.round(np.linspace(0, kept.size - 1, limit // 2)).astype(int))]
    chosen = list(kept)
    rest = np.flatnonzero(~keep)
    room = limit - len(chosen)
    if room > 0 and rest.size:
        pick = np.unique(np.round(np.linspace(0, rest.size - 1, room)).astype(int))
        chosen += list(rest[pick])
    return np.sort(np.asarray(chosen, int))


def _check_settings_gammas(settings: np.ndarray, gammas) -> None:
    """Every angle of incidence of ``settings_deg`` is one the instrument lists: a setting at
    another was proposed as if the instrument could set it."""
    listed = np.abs(np.asarray(gammas, float))
    mags = np.unique(np.round(np.abs(settings[:, 0]), 9))
    off = [m for m in mags if not np.any(np.abs(listed - m) <= 1e-6)]
    if off:
        raise IrreflectError(
            f"settings_deg: angle(s) of incidence {', '.join(f'{m:g}' for m in off[:5])} deg "
            f"are not among gammas_deg ({', '.join(f'{m:g}' for m in listed)}): list them "
            "in gammas_deg, or leave those settings out")


def _checked_settings(settings_deg) -> np.ndarray:
    """``settings_deg`` as an ``(n, 2)`` array of (gamma, theta) in degrees, gammas given
    as magnitudes read as ``-|gamma|`` (as ``gammas_deg``), or a one-line error."""
    try:
        s = np.array(settings_deg, float)
    except (TypeError, ValueError):
        s = np.zeros((0, 3))
    if s.ndim != 2 or s.shape[1] != 2 or not len(s) or not np.all(np.isfinite(s)):
        raise IrreflectError(
            "settings_deg must be (gamma, theta) pairs in degrees, an array of shape "
            f"(n, 2) of finite numbers; found shape {s.shape}: give one row per setting")
    if np.any(np.abs(s) >= 90):
        raise IrreflectError(f"settings_deg: angles must lie strictly between -90 and "
                             f"90 degrees; found {s[np.abs(s) >= 90][0]:g}")
    if np.any(s[:, 0] > 0) and np.any(s[:, 0] < 0):
        raise IrreflectError(
            "settings_deg: the angles of incidence mix signs, which is ambiguous: give "
            "them all <= 0 (the paper's convention) or all as magnitudes >= 0")
    s[:, 0] = -np.abs(s[:, 0]) + 0.0  # magnitudes, as gammas_deg (theta kept)
    return s


def _close_pairs(gamma_deg: np.ndarray, theta_deg: np.ndarray, separation: float) -> list:
    """Neighbouring readings of one angle of incidence closer than ``separation`` along
    theta (distinct settings; a repeated one is refused before this): ``(gamma, theta,
    theta)`` each, in the order of gamma then theta."""
    out = []
    for x in np.unique(np.round(gamma_deg, 6)):
        ts = np.sort(theta_deg[np.round(gamma_deg, 6) == x])
        gaps = np.diff(ts)
        for i in np.flatnonzero(gaps < separation - 1e-9):
            out.append((float(x), float(ts[i]), float(ts[i + 1])))
    return out

