"""Measurement tables: read, validate, write; the bundled and the real datasets.

A table has columns ``gamma_deg, theta_deg, power`` and optionally ``sigma`` (1-sigma
uncertainty of power) and ``material``; CSV or Parquet. Angles in degrees, in the
paper's convention: gamma negative on the source side, mirror direction theta = -gamma.

Every check raises :class:`~irreflect.errors.DataError` with one line saying what was
expected, what was found and how to fix it.
"""

from __future__ import annotations

import csv
import difflib
import os
import re
import warnings
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from ._atomic import atomic_path
from ._inputs import read_bytes
from .errors import DataError, IrreflectError, unknown_name
from .paper import real_data_dir as _real
from .validation import (
    MAX_FILE_BYTES,
    MAX_TABLE_ROWS,
    check_bool,
    check_number,
    check_real_array,
    short_list,
)

REQUIRED = ("gamma_deg", "theta_deg", "power")
OPTIONAL = ("sigma", "material")
#: A negative power is accepted as noise around zero only down to this fraction of the
#: table's maximum power (or 4 sigma, when sigma is given; or, without sigma, 5 times the
#: noise the negative readings themselves show, up to NEGATIVE_NOISE_MAX of the maximum:
#: :func:`_negative_noise`).
NEGATIVE_POWER_TOLERANCE = 0.02
#: A campaign's readings so far (``partial``) may hold a lone reading of noise around
#: zero (a reading beyond a glossy lobe is 0, and with few readings their peak may be
#: small), so the allowance is wider than a whole table's: a reading below -this share of a
#: larger positive reading (and below -4 sigma) is a sign or offset error
#: (:func:`_check_partial_negative`).
PARTIAL_NEGATIVE_TOLERANCE = 0.25
NEGATIVE_NOISE_MAX = 0.05
#: The largest |power| of a table must lie in this range (squares and sums of squares of
#: the fit stay finite and above underflow); any unit can be rescaled into it.
POWER_RANGE = (1e-100, 1e100)
#: Angles of incidence closer than this (deg) to the next one are one setting read with
#: jitter (a goniometer reporting its encoder: -9.98, -10.01, -10.02 for -10), when the
#: run of them spans at most :data:`GAMMA_JITTER_SPAN`; they are read at the run's mean.
GAMMA_JITTER_GAP = 0.1
GAMMA_JITTER_SPAN = 0.25


class DataNotice(UserWarning):
    """Something the reader did to a table that the user should know about."""


@dataclass(frozen=True)
class Measurements:
    """A validated measurement table (angles in degrees, paper convention)."""

    gamma_deg: np.ndarray
    theta_deg: np.ndarray
    power: np.ndarray
    sigma: np.ndarray | None = None
    material: str | None = None
    name: str = "measurements"
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self):
        # arrays of real, finite numbers, one per point (lists are converted)
        source = f"Measurements '{self.name}'"
        _check_series_aligned(self, source)
        arrays = {k: check_real_array(getattr(self, k), k, source=source)
                  for k in ("gamma_deg", "theta_deg", "power")}
        if self.sigma is not None:
            arrays["sigma"] = check_real_array(self.sigma, "sigma", source=source)
        sizes = {k: v.size for k, v in arrays.items()}
        if len(set(sizes.values())) > 1:
            _fail(f"{source}: gamma_deg, theta_deg, power (and sigma) need one value per "
                  f"point; found lengths {', '.join(f'{k} {n}' for k, n in sizes.items())}")
        if not isinstance(self.name, str):
            _fail(f"Measurements: name must be text; found {self.name!r}")
        if sizes["power"] == 0:
            _fail(f"{source}: no points: expected at least one measurement")
        for k in ("gamma_deg", "theta_deg"):
            out = np.abs(arrays[k]) >= 90
            if out.any():
                _fail(f"{source}: {k} must lie strictly between -90 and 90 degrees (from the "
                      f"surface normal); found {arrays[k][out][0]:g}")
        if "sigma" in arrays:  # sigma <= 0 is the fit's to refuse (a table may carry it)
            check_sigma(arrays["power"], arrays["sigma"], source, positive=False)
        for k, v in arrays.items():
            object.__setattr__(self, k, v)

    @property
    def n_points(self) -> int:
        return int(self.power.size)

    @property
    def gammas(self) -> np.ndarray:
        """Distinct angles of incidence, by increasing magnitude."""
        g = np.unique(self.gamma_deg)
        return g[np.argsort(np.abs(g), kind="stable")]

    def to_frame(self) -> pd.DataFrame:
        data = {"gamma_deg": self.gamma_deg, "theta_deg": self.theta_deg, "power": self.power}
        if self.sigma is not None:
            data["sigma"] = self.sigma
        df = pd.DataFrame(data)
        if self.material is not None:
            df["material"] = self.material
        return df

    def subset(self, mask) -> Measurements:
        mask = np.asarray(mask)
        return replace(
            self,
            gamma_deg=self.gamma_deg[mask],
            theta_deg=self.theta_deg[mask],
            power=self.power[mask],
            sigma=None if self.sigma is None else self.sigma[mask],
        )


def _fail(msg: str):
    raise DataError(msg)


def _check_series_aligned(meas, source: str) -> None:
    """pandas Series given for the columns of a :class:`Measurements` pair up by position
    once converted to arrays: refuse Series whose indexes differ (they would pair the
    rows of different labels)."""
    series = {k: getattr(meas, k) for k in ("gamma_deg", "theta_deg", "power", "sigma")
              if isinstance(getattr(meas, k), pd.Series)}
    if len(series) < 2:
        return
    (first, ref), *rest = series.items()
    for k, s in rest:
        if not s.index.equals(ref.index):
            def shown(index):
                return short_list(index[:3].tolist(), 3) + (", ..." if len(index) > 3 else "")
            _fail(f"{source}: {first} and {k} are pandas Series with different indexes "
                  f"({shown(ref.index)} and {shown(s.index)}), which would pair their values "
                  "by position, not by label: take them from one DataFrame, call "
                  ".reset_index(drop=True) on each, or pass arrays (.to_numpy())")


#: sigma must lie within these multiples of the largest |power|: weights 1/sigma^2 beyond
#: them over- or underflow in the fit.
SIGMA_RANGE = (1e-12, 1e12)


def check_sigma(power: np.ndarray, sigma: np.ndarray, source: str, rows=None,
                positive: bool = True) -> None:
    """sigma > 0 (with ``positive``; else the fit refuses it) and within
    :data:`SIGMA_RANGE` of the largest |power| (one line naming the row)."""
    rows = rows or (lambda i: f"point {i + 1}")
    if positive and np.any(sigma <= 0):
        i = int(np.nonzero(sigma <= 0)[0][0])
        _fail(f"{source}: sigma must be > 0 (fits are weighted by 1/sigma^2); found "
              f"{sigma[i]:g} in {rows(i)}: give that point's uncertainty, or drop sigma to fit "
              "unweighted")
    peak = float(np.max(np.abs(power)))
    if peak == 0:
        return
    low, high = SIGMA_RANGE[0] * peak, SIGMA_RANGE[1] * peak
    bad = ((sigma < low) & (sigma > 0)) | (sigma > high)
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        side = "below 1e-12 of" if sigma[i] < low else "above 1e12 times"
        _fail(f"{source}: sigma {sigma[i]:g} in {rows(i)} is {side} the largest power "
              f"({peak:g}): weights 1/sigma^2 that {'large' if sigma[i] < low else 'small'} "
              "cannot be fitted; give a realistic uncertainty or delete the sigma column")


# ----------------------------------------------------------------------------- row labels
class _Rows:
    """How a message names data row ``i`` (0-based): with the file line for a CSV."""

    def __init__(self, lines=None, index=None):
        self.lines = lines
        self.index = index  # the table's row of each row kept (rows left out before)

    def __call__(self, i: int) -> str:
        i = int(self.index[i]) if self.index is not None else i
        if self.lines is None:
            return f"data row {i + 1}"
        return f"data row {i + 1} (line {self.lines[i]})"

    def kept(self, index) -> _Rows:
        """The labels of the rows ``index`` (of the rows so far) once the others are left out."""
        index = np.asarray(index)
        return _Rows(self.lines, index if self.index is None else self.index[index])


_MISSING = {"", "nan", "na", "n/a", "null", "none"}


def _check_columns(df: pd.DataFrame, source: str) -> pd.DataFrame:
    if isinstance(df.columns, pd.MultiIndex):
        _fail(f"{source}: the table has multi-level column names "
              f"({short_list(df.columns[:3].tolist(), 3)}); expected one header row: flatten "
              "them to gamma_deg, theta_deg, power")
    cols = [str(c).strip() for c in df.columns]
    seen: dict[str, int] = {}
    for i, c in enumerate(cols):
        if c in seen and c:
            _fail(f"{source}: column '{c}' appears twice (columns {seen[c] + 1} and {i + 1}): "
                  "keep one, or rename the other")
        seen[c] = i
    df = df.set_axis(cols, axis=1)
    for need in REQUIRED:
        if need in cols:
            continue
        candidates = [c for c in cols if c not in REQUIRED + OPTIONAL]
        lower = {c.lower(): c for c in candidates}
        close = difflib.get_close_matches(need, candidates, n=1, cutoff=0.5)
        if need in lower:
            close = [lower[need]]
        hint = f"; found '{close[0]}': rename it to '{need}'" if close else ""
        if len(cols) == 1 and _separator_hint(cols[0]):
            hint = _separator_hint(cols[0])
        if not hint and cols and all(_looks_numeric(c) for c in cols if c):
            hint = ("; the first line holds numbers, not names: add the header line "
                    "gamma_deg,theta_deg,power")
        _fail(
            f"{source}: missing column '{need}': expected columns gamma_deg, theta_deg, power "
            f"(optional sigma, material), found {short_list(cols) or 'none'}{hint}"
        )
    return df


#: A number followed by a unit's name ("1.2 mW", "-3dBm", "45 deg", "12%").
_WITH_UNIT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*([^\d\s.,+-].*)$")


def _unit_hint(bad_text: pd.Series, n_bad: int, n_rows: int, col: str) -> str:
    """How to fix numbers written with their unit: "fix or remove that row" misled when
    every row of the column said "1.2 mW"."""
    units = sorted({m.group(3).strip() for t in bad_text
                    if (m := _WITH_UNIT.match(str(t).strip()))})
    shown = ", ".join(f"'{u}'" for u in units[:4]) + (", ..." if len(units) > 4 else "")
    if col != "power":
        return f"{n_bad} of {n_rows} rows carry a unit ({shown}): write the angles alone, in degrees"
    if any(u.lower().startswith("db") for u in units):
        return (f"{n_bad} of {n_rows} rows carry a unit ({shown}): the model fits linear power; "
                "convert decibels to it (mW = 10^(dBm/10)) and write the numbers alone")
    if len(units) > 1:
        return (f"{n_bad} of {n_rows} rows carry a unit and they differ ({shown}): convert "
                "the column to one unit and write the numbers alone")
    if n_bad < n_rows:
        return (f"{n_bad} of {n_rows} rows carry a unit ({shown}): write them as numbers alone, "
                "in the unit of the other rows")
    return (f"write the numbers alone, without their unit {shown} (every row carries it; any "
            "one unit works for the whole column)")


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _clip(text: str, width: int = 60) -> str:
    text = text.replace("\t", "\\t")
    return text if len(text) <= width else text[: width - 3] + "..."


def _separator_hint(header: str) -> str:
    for sep, name in ((";", "';'"), ("\t", "tabs"), ("|", "'|'")):
        if sep in header:
            return (f"; the file is separated by {name}, expected commas: save it with commas "
                    "between columns (and '.' as the decimal point)")
    return ""


def _bad_sigma(sigma, rows, source) -> None:
    """Refuse sigma <= 0, saying how many rows hold it: a column of zeros (an instrument
    that writes 0 when it computes no uncertainty; unseen_tables3's sigma_all_zero) was
    told only of its first row, as if one reading needed fixing."""
    bad = np.nonzero(sigma <= 0)[0]
    i = int(bad[0])
    if bad.size == sigma.size > 1:
        _fail(f"{source}: sigma must be > 0 (a 1-sigma uncertainty; fits are weighted by "
              f"1/sigma^2); found <= 0 in all {sigma.size} rows (max {np.max(sigma):g}): the "
              "column holds no uncertainties; delete the sigma column to fit unweighted")
    many = f" and {bad.size - 1} more row(s)" if bad.size > 1 else ""
    _fail(
        f"{source}: sigma must be > 0 (a 1-sigma uncertainty; fits are weighted by "
        f"1/sigma^2); found {sigma[i]:g} in {rows(i)}{many} (of {sigma.size}): give those "
        "rows' uncertainty, or delete the sigma column to fit unweighted"
    )

def _numeric(df: pd.DataFrame, col: str, source: str, rows: _Rows) -> np.ndarray:
    raw = df[col]
    kind = pd.api.types.infer_dtype(raw, skipna=True)
    if kind == "boolean" or raw.dtype == bool:
        _fail(f"{source}: column '{col}' holds true/false values; expected numbers "
              f"({'power in the detector unit' if col == 'power' else 'degrees'})")
    if kind == "complex" or np.iscomplexobj(raw.to_numpy()):
        _fail(f"{source}: column '{col}' holds complex numbers; expected real numbers: store "
              "the magnitude (abs) or the real part")
    if kind.startswith(("datetime", "timedelta", "date", "time", "period", "interval")):
        _fail(f"{source}: column '{col}' holds {kind} values; expected numbers")
    if raw.dtype.kind in "iuf":
        arr = raw.to_numpy(dtype=float)
    else:
        text = raw.astype(str).str.strip()
        missing = raw.isna().to_numpy() | text.str.lower().isin(_MISSING).to_numpy()
        values = pd.to_numeric(text.where(~missing, "nan"), errors="coerce")
        bad = values.isna().to_numpy() & ~missing
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            found = str(raw.iloc[i])
            hint = "fix or remove that row"
            if "," in found and _looks_numeric(found.replace(",", ".")):
                hint = "use '.' as the decimal point (found a decimal comma)"
            elif _WITH_UNIT.match(found.strip()):
                hint = _unit_hint(text[bad], int(bad.sum()), len(raw), col)
            elif bad.sum() > 1:
                hint = f"fix or remove that row ({int(bad.sum()) - 1} more row(s) like it)"
            _fail(
                f"{source}: column '{col}' must be numeric; found '{found}' in {rows(i)}: {hint}"
            )
        arr = values.to_numpy(dtype=float)
    nonfinite = ~np.isfinite(arr)
    if nonfinite.any():
        i = int(np.nonzero(nonfinite)[0][0])
        _fail(
            f"{source}: column '{col}' has {int(nonfinite.sum())} empty, NaN or infinite value(s), "
            f"first in {rows(i)}: measure it again or remove the row"
        )
    return arr


def _leave_out_grazing(gamma, theta, power, sigma, rows, source):
    """The rows with an angle of exactly +-90 deg (the source or the receiver in the surface
    plane: a goniometer that sweeps -90..90 writes them; the model has no power there to
    fit) left out, with a note; an angle beyond +-90 deg is an error."""
    for col, arr in (("gamma_deg", gamma), ("theta_deg", theta)):
        out = np.abs(arr) > 90 + 1e-9
        if out.any():
            i = int(np.nonzero(out)[0][0])
            _fail(f"{source}: {col} must lie within -90 and 90 degrees; found {arr[i]:g} in "
                  f"{rows(i)}: angles are in degrees from the surface normal")
    at = (np.abs(gamma) >= 90 - 1e-9) | (np.abs(theta) >= 90 - 1e-9)
    if not at.any():
        return gamma, theta, power, sigma, rows, None
    if at.all():
        _fail(f"{source}: every row has an angle of +-90 deg (in the surface plane): nothing "
              "to fit; angles are in degrees from the surface normal, strictly between -90 "
              "and 90")
    keep = np.nonzero(~at)[0]
    note = (f"{source}: left out {int(at.sum())} row(s) at gamma or theta = +-90 deg (first "
            f"{rows(int(np.argmax(at)))}): the source or the receiver lies in the surface "
            "plane there, where the model has no power to fit")
    return (gamma[keep], theta[keep], power[keep], None if sigma is None else sigma[keep],
            rows.kept(keep), note)


#: :func:`saturation_note`: this many settings or more reading exactly the largest power.
SATURATED_SETTINGS = 3


def saturation_note(gamma, power, source) -> str | None:
    """A note when :data:`SATURATED_SETTINGS` or more settings read exactly the largest
    power, and no more than half of them: a detector (or its amplifier or converter) at the
    top of its range (a table of one power is refused on its own). Clipped
    readings flatten the lobe's top, and a fit widens the lobe to match. (Held-out tables
    with a clipped peak tie 4-92 settings at the maximum; no real, bundled or other
    held-out table ties two.)"""
    found = saturated_readings(gamma, power)
    if found is None:
        return None
    count, top, n_angles = found
    return (f"{source}: {count} readings ({count / np.size(power):.0%}) equal the largest "
            f"power, {top:g}, exactly, at {n_angles} angle(s) of incidence: a saturated "
            "detector? Clipped readings flatten the lobe's top and widen the fitted lobe: "
            "measure them again with less gain, or leave them out")


def saturated_readings(gamma, power) -> tuple[int, float, int] | None:
    """(how many readings equal the largest power exactly, that power, at how many angles of
    incidence) when they look like a clipped detector (:func:`saturation_note`), else None."""
    power = np.asarray(power, float)
    top = float(np.max(power)) if power.size else float("nan")
    if not top > 0:
        return None
    at = np.abs(power - top) <= 1e-12 * top
    count = int(at.sum())
    if count < SATURATED_SETTINGS or count > power.size / 2:  # (all equal: power constant)
        return None
    return count, top, int(np.unique(np.round(np.asarray(gamma, float)[at], 6)).size)


def _angle_notes(gamma, theta, partial, source) -> tuple[np.ndarray, list[str]]:
    """The angles of incidence read as their settings (:func:`_group_jittered_gammas`)
    and the notes on a table's angles: that jitter, and angles that look like radians."""
    gamma, jitter_note = _group_jittered_gammas(gamma, source)
    notes = [jitter_note] if jitter_note else []
    if not partial and _looks_like_radians(gamma, theta):
        notes.append(f"{source}: every angle lies within +-{np.pi / 2:.4g} (pi/2) and the "
                     f"receiver angles span only {np.ptp(theta):.3g}: the file may give "
                     "radians, and irreflect reads degrees (multiply gamma_deg and theta_deg "
                     "by 180/pi if so)")
    return gamma, notes


def _looks_like_radians(gamma, theta) -> bool:
    """Angles that all lie within +-pi/2 while the receiver sweeps more than 0.5 of them
    over five or more distinct values: a table in radians (read as degrees, a scan of
    +-1.5 deg fitted without a word)."""
    limit = np.pi / 2 + 1e-9
    return bool(np.all(np.abs(gamma) <= limit) and np.all(np.abs(theta) <= limit)
                and np.ptp(theta) > 0.5 and np.unique(theta).size >= 5)


def _group_jittered_gammas(gamma, source) -> tuple[np.ndarray, str | None]:
    """Angles of incidence read with jitter, as one setting each: runs of distinct values
    less than :data:`GAMMA_JITTER_GAP` apart, each spanning at most
    :data:`GAMMA_JITTER_SPAN`, are read at the run's mean (to 0.01 deg), with a note. A
    table of 108 rows whose gammas were 7 settings plus +-0.02 deg of noise was read as
    108 angles of incidence: the fit's verdict listed each, the campaign searched 204,156
    triples of them for 82 s, and diagnose found no run of receivers to judge the noise on.
    Runs spanning more (a fine sweep of gamma) are left as measured."""
    values = np.unique(gamma)
    if values.size < 2:
        return gamma, None
    breaks = np.flatnonzero(np.diff(values) >= GAMMA_JITTER_GAP) + 1
    runs = np.split(values, breaks)
    if len(runs) == values.size or any(r[-1] - r[0] > GAMMA_JITTER_SPAN for r in runs):
        return gamma, None
    run_of = np.searchsorted(values[breaks], gamma, side="right")
    means = np.array([np.round(np.mean(gamma[run_of == k]), 2) for k in range(len(runs))])
    widest = max(r[-1] - r[0] for r in runs)
    note = (f"{source}: gamma_deg holds {values.size} distinct values in {len(runs)} groups, "
            f"each within {widest:.3g} deg: read as {len(runs)} angles of incidence with "
            "jitter, each at its group's mean ("
            + ", ".join(f"{m:g}" for m in means[np.argsort(np.abs(means), kind='stable')])
            + " deg); round gamma_deg in the file to the settings to read them otherwise")
    return means[run_of], note


def _merge_duplicates(gamma, theta, power, sigma, source, rows, average):
    """Duplicated (gamma, theta) rows refused, or with ``average`` merged (power averaged,
    sigma combined): returns (gamma, theta, power, sigma, rows merged)."""
    key = pd.DataFrame({"g": gamma, "t": theta})
    dup = key.duplicated(keep=False).to_numpy()
    if dup.any():
        if not average:
            i = int(np.nonzero(dup)[0][0])
            _fail(
                f"{source}: {int(key.duplicated().sum())} duplicated (gamma_deg, theta_deg) rows, "
                f"first ({gamma[i]:g}, {theta[i]:g}) at {rows(i)}: remove them or average "
                "their power into one row (--average-duplicates; average_duplicates=True of "
                "read_measurements and validate_table)"
            )
        frame = pd.DataFrame({"g": gamma, "t": theta, "p": power})
        if sigma is not None:
            frame["s2"] = sigma**2
        grouped = frame.groupby(["g", "t"], sort=False)
        agg = grouped.agg(p=("p", "mean"), k=("p", "size"), lo=("p", "min"), hi=("p", "max"))
        if sigma is not None:
            agg["s"] = np.sqrt(grouped["s2"].sum()) / agg["k"]
        n_merged = int(len(frame) - len(agg))
        gamma = agg.index.get_level_values(0).to_numpy(float)
        theta = agg.index.get_level_values(1).to_numpy(float)
        power = agg["p"].to_numpy(float)
        sigma = agg["s"].to_numpy(float) if sigma is not None else None
        return gamma, theta, power, sigma, _merged_note(agg, n_merged, source)
    return gamma, theta, power, sigma, ""


def _merged_note(agg: pd.DataFrame, n_merged: int, source: str) -> str:
    """The note on averaged duplicates, with how far the repeats of one setting disagree
    (repeats 50 % apart were averaged with only "averaged 5 duplicated row(s)")."""
    note = f"{source}: averaged {n_merged} duplicated (gamma, theta) row(s)"
    spread = (agg["hi"] - agg["lo"]).to_numpy(float)
    scale = float(np.max(np.abs(agg["p"].to_numpy(float))))
    if not np.any(spread > 0) or scale <= 0:
        return note + " (equal powers)"
    i = int(np.argmax(spread))
    g, t = agg.index[i]
    mean = abs(float(agg["p"].iloc[i]))
    rel = f"{spread[i] / mean:.0%} of their mean, " if mean > 0 else ""
    return (note + f"; the repeats of one setting differ by up to {spread[i]:.3g} ({rel}"
            f"{spread[i] / scale:.1%} of the largest power) at gamma {g:g}, theta {t:g}")


def _peak_sides(gamma, theta, power) -> list[int]:
    """For each angle of incidence (a magnitude above 2 deg with readings on both sides of
    the normal): +1 when its highest reading lies at the mirror of the magnitude frame
    (theta = +|gamma|), -1 when at theta = -|gamma|, 0 when neither or both (a curve with
    no clear specular peak)."""
    sides = []
    mags = np.abs(gamma)
    order = np.argsort(mags, kind="stable")
    values, starts = np.unique(mags[order], return_index=True)
    for g, at in zip(values, np.split(order, starts[1:]), strict=True):
        t, p = theta[at], power[at]
        if g < 2.0 or t.size < 4 or not (np.any(t > 0) and np.any(t < 0)):
            continue
        step = float(np.median(np.diff(np.unique(t)))) if np.unique(t).size > 1 else 1.0
        near = max(3.0, 1.5 * step)
        # every reading tied at the highest power (a clipped lobe's top, or a constant
        # curve): a side only when all of them stand at it (a flat table's first reading
        # had made it 'peak at the source direction')
        top = t[p >= np.max(p)]
        plus = bool(np.all(np.abs(top - g) <= near))
        minus = bool(np.all(np.abs(top + g) <= near))
        sides.append(int(plus) - int(minus))
    return sides


def _negative_noise(power) -> float | None:
    """The additive noise (1 sigma) a table without a sigma column shows through its
    negative readings, when they look like noise around zero: at least 5 of them, the
    largest |power| positive (not a sign error), as many small positive readings (up to
    the deepest negative one) as half the negatives (noise is symmetric; a detector offset
    pushes the dark readings all one way), and the deepest within 5 times their RMS (no
    lone outlier). None otherwise."""
    neg = power[power < 0]
    peak = float(np.max(np.abs(power)))
    if neg.size < 5 or not np.max(power) >= peak:
        return None
    rms = float(np.sqrt(np.mean(neg ** 2)))
    deepest = float(-neg.min())
    small = int(np.sum((power > 0) & (power <= deepest)))
    if small < 0.5 * neg.size or deepest > 5.0 * rms or rms > NEGATIVE_NOISE_MAX * peak:
        return None
    return rms


#: How a table (or a protocol file) in the paper's frame mirrored is read.
MIRRORED_FRAME = ("read as the paper's frame mirrored (gamma and theta both change sign, the "
                  "mirror direction stays theta = -gamma)")


def _frame(gamma, theta, power, positive: bool, partial: bool, source):
    """The paper's frame of a table's angles and the notes on it: gammas all >= 0 read as
    magnitudes, or as the paper's frame mirrored when the readings peak at theta = -gamma
    (:func:`_peak_sides`; a campaign's readings so far, ``partial``, are then refused); a
    note when a table in the paper's convention peaks at the source direction."""
    out = []
    if positive:
        sides = _peak_sides(gamma, theta, power)
        if partial and sides and all(side < 0 for side in sides):
            # a campaign's proposals are in the paper's frame: rows added from them to a
            # file in the mirrored frame would mix the two, so it is refused, not turned
            _fail(f"{source}: all gamma_deg >= 0 and the readings peak at theta = -gamma at "
                  "every angle of incidence: the file looks like the paper's frame mirrored, "
                  "which a campaign does not read (its proposals are in the paper's frame): "
                  "change the sign of both gamma_deg and theta_deg; if the gammas are "
                  "magnitudes with the mirror at theta = +gamma, make them negative instead")
        if sides and all(side < 0 for side in sides):
            # the readings peak at theta = -gamma in the file's own signs: the paper's frame
            # mirrored (source on the positive side), so theta turns with gamma
            gamma, theta = -gamma, -theta
            out.append(f"{source}: all gamma_deg >= 0 and the readings peak at theta = "
                      f"-gamma at every angle of incidence: {MIRRORED_FRAME}")
        else:
            gamma = -gamma
            out.append(f"{source}: all gamma_deg >= 0, read as magnitudes (gamma = "
                      "-|gamma|) with the mirror direction on the positive-theta side")
    elif not partial:
        sides = _peak_sides(gamma, theta, power)
        if sides and all(side < 0 for side in sides):
            out.append(f"{source}: the readings peak at theta = gamma (the source direction "
                      "in the paper's convention) at every angle of incidence, not at the "
                      "mirror theta = -gamma: if theta was counted positive on the source "
                      "side, change its sign (a retroreflector may peak there)")
    return gamma, theta, out


def _check_negative_power(power, sigma, source, rows):
    """Negative powers: only small noise around zero (else one line); returns the note on
    those kept, or None."""
    neg = power < 0
    if neg.any():
        limit = NEGATIVE_POWER_TOLERANCE * max(np.max(np.abs(power)), 1e-300)
        noise = None
        if sigma is not None:
            limit = np.maximum(limit, 4 * sigma)
        else:
            noise = _negative_noise(power)
            if noise is not None and 5.0 * noise > limit:
                limit = 5.0 * noise
            else:
                noise = None
        too_neg = power < -np.broadcast_to(limit, power.shape)
        if too_neg.any():
            i = int(np.nonzero(too_neg)[0][0])
            _fail(
                f"{source}: power must be >= 0 up to noise; found {power[i]:g} at {rows(i)}, "
                f"below the noise allowance {-np.broadcast_to(limit, power.shape)[i]:g}: check the "
                "detector offset or the sign of the column"
                + ("" if sigma is not None else
                   f", or give the noise as a sigma column (negative power down to -4 sigma "
                   f"is kept; without it, down to -{NEGATIVE_POWER_TOLERANCE:.0%} of the "
                   "largest power)")
            )
        if noise is not None:
            return (f"{source}: {int(neg.sum())} negative power value(s) kept as noise around "
                    f"zero (they show an additive noise of {noise:.3g}, "
                    f"{noise / np.max(power):.1%} of the largest power; give a sigma column "
                    "to weight the fit by it)")
        return (f"{source}: {int(neg.sum())} slightly negative power value(s) kept as noise "
                "around zero")
    return None


def _one_material(df: pd.DataFrame, source: str) -> str | None:
    """The table's material (None without a material column); a table naming two or more
    is refused: it holds one material's readings. Blank and NaN cells name none."""
    if "material" not in df.columns:
        return None
    mats = df["material"].dropna().astype(str).str.strip()
    mats = mats[(mats != "") & (mats.str.lower() != "nan")].unique()
    if len(mats) > 1:
        _fail(f"{source}: the material column names {len(mats)} materials "
              f"({short_list(list(mats), 4)}): a table holds one material's readings; "
              "split it into one table per material")
    return mats[0] if len(mats) else None


def _check_partial_negative(power, sigma, source, rows, noise_floor: float = 0.0) -> None:
    """Negative readings of a campaign (see :data:`PARTIAL_NEGATIVE_TOLERANCE`): refused
    when most of at least four nonzero readings are negative, or when a reading lies below
    -that share of a larger positive reading (and below -4 sigma), or (with at least four
    nonzero readings) below every positive one and 4 times the median |reading| (a peak with
    its sign flipped); a negative reading with no larger positive one beside it and of the
    size of the others may be noise around a small signal, and is kept."""
    neg = power < -noise_floor  # within the known noise floor: noise, not a sign error
    if not neg.any():
        return
    nonzero = int(np.count_nonzero(np.abs(power) > noise_floor))
    if nonzero >= 4 and 2 * int(neg.sum()) > nonzero:
        _fail(f"{source}: power must be >= 0 up to noise; {int(neg.sum())} of the "
              f"{nonzero} nonzero readings are negative: check the detector offset or the "
              "sign of the column")
    top = float(np.max(power))
    limit = np.full(power.shape, max(PARTIAL_NEGATIVE_TOLERANCE * max(top, 0.0), noise_floor))
    if sigma is not None:
        limit = np.maximum(limit, 4.0 * sigma)
    bad = (power < -limit) & (-power <= top)
    if nonzero >= 4:
        # larger than every positive reading and far above the typical one: a peak typed
        # with its sign flipped, not noise around a small signal
        typical = float(np.median(np.abs(power[power != 0])))
        bad |= (power < -limit) & (-power > top) & (-power > 4.0 * typical)
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        _fail(f"{source}: power must be >= 0 up to noise; found {power[i]:g} at {rows(i)}, "
              f"beyond {PARTIAL_NEGATIVE_TOLERANCE:.0%} of the largest reading ({top:g}): "
              "check the detector offset or the sign of the column, or give the readings' "
              "noise (a sigma column; down to -4 sigma is kept)")


def validate_table(df: pd.DataFrame, source: str = "table", *,
                   average_duplicates: bool = False, name: str | None = None,
                   partial: bool = False, noise_floor: float = 0.0,
                   _row_lines=None) -> Measurements:
    """Check a table and convert it to :class:`Measurements` (see the module docstring).

    ``partial``: the table is a campaign's readings so far, not a table to fit on its own:
    power may be 0 (or tiny) in every row and a reading may be negative noise, which a
    whole table would refuse (a reading beyond the lobe of a glossy material is 0; one
    reading of additive noise is as often below 0 as above). ``noise_floor`` (power units,
    partial tables only): a negative reading down to minus this is noise, whatever the
    other readings (the detector's dark noise, known beforehand: a campaign's first
    readings can be too few and too small to tell noise from a sign error)."""
    if not isinstance(df, pd.DataFrame):
        _fail(f"{source}: expected a table (pandas DataFrame), found {type(df).__name__}")
    average_duplicates = check_bool(average_duplicates, "average_duplicates")  # 'no' is true
    partial = check_bool(partial, "partial")
    noise_floor = check_number(noise_floor, "noise_floor", low=0.0)
    rows = _Rows(_row_lines)
    df = _check_columns(df, source)
    if len(df) == 0:
        _fail(f"{source}: the table has no rows: expected at least one measurement")
    if len(df) > MAX_TABLE_ROWS:
        _fail(f"{source}: {len(df)} rows is more than irreflect reads ({MAX_TABLE_ROWS}): "
              "subsample the table")
    # + 0.0: an angle written -0.0 (a script's rounding) is 0, not "-0" in every message
    gamma = _numeric(df, "gamma_deg", source, rows) + 0.0
    theta = _numeric(df, "theta_deg", source, rows) + 0.0
    power = _numeric(df, "power", source, rows)
    sigma = _numeric(df, "sigma", source, rows) if "sigma" in df.columns else None
    notes = []
    gamma, theta, power, sigma, rows, grazing = _leave_out_grazing(gamma, theta, power, sigma,
                                                                  rows, source)
    if grazing:
        notes.append(grazing)
    if sigma is not None and np.any(sigma <= 0):
        _bad_sigma(sigma, rows, source)
    peak = float(np.max(np.abs(power)))
    if partial and peak < POWER_RANGE[0]:
        peak = POWER_RANGE[0]
    if peak == 0:
        _fail(f"{source}: power is 0 in every row: nothing to fit; check the detector and the "
              "column")
    if not POWER_RANGE[0] <= peak <= POWER_RANGE[1]:
        _fail(f"{source}: the largest |power| is {peak:g}, outside what the fitter handles "
              f"({POWER_RANGE[0]:g} to {POWER_RANGE[1]:g}): rescale the column (any consistent "
              "unit works, e.g. divide by its maximum)")
    if sigma is not None:
        check_sigma(power, sigma, source, rows)
    positive, negative = np.any(gamma > 0), np.any(gamma < 0)
    if positive and negative:
        # name a value of each sign: a lone 1e-12 among negative angles read as a bare
        # "mixes positive and negative" left the user to search the file for it
        ip, ineg = int(np.flatnonzero(gamma > 0)[0]), int(np.flatnonzero(gamma < 0)[0])
        _fail(
            f"{source}: gamma_deg mixes positive and negative angles of incidence, which is "
            f"ambiguous; found {int(np.sum(gamma > 0))} positive (first {gamma[ip]:g} at "
            f"{rows(ip)}) and {int(np.sum(gamma < 0))} negative (first {gamma[ineg]:g} at "
            f"{rows(ineg)}): use the paper's convention (all <= 0, source side) or magnitudes "
            "(all >= 0)"
        )
    if positive or not partial:
        gamma, theta, frame_notes = _frame(gamma, theta, power, positive, partial, source)
        notes += frame_notes
    gamma, angle_notes = _angle_notes(gamma, theta, partial, source)
    notes += angle_notes
    material = _one_material(df, source)
    gamma, theta, power, sigma, merged = _merge_duplicates(gamma, theta, power, sigma, source,
                                                           rows, average_duplicates)
    if merged:
        notes.append(merged)
        rows = _Rows()  # row numbers no longer match the file
    if partial:
        _check_partial_negative(power, sigma, source, rows, noise_floor)
    # a campaign's readings (partial) too can be clipped: 3 of its first 8 at exactly the
    # largest power say as much as 3 of a dense table's
    for note in ((saturation_note(gamma, power, source),) if partial else
                 (_check_negative_power(power, sigma, source, rows),
                  saturation_note(gamma, power, source))):
        if note:
            notes.append(note)
    for note in notes:  # said once per table; the CLI prints them as "irreflect: note: ..."
        warnings.warn(note, DataNotice, stacklevel=3)
    return Measurements(
        gamma_deg=gamma, theta_deg=theta, power=power, sigma=sigma, material=material,
        name=name or Path(str(source)).stem, notes=tuple(notes),
    )


# ----------------------------------------------------------------------------- files
_SUFFIXES = (".csv", ".txt", "", ".parquet", ".pq")


#: The note a table read with ``ignore_sigma`` carries when it had a sigma column.
SIGMA_LEFT_OUT = "sigma column left out, unchecked (ignore_sigma)"


def read_measurements(path, *, average_duplicates: bool = False,
                      partial: bool = False, ignore_sigma: bool = False) -> Measurements:
    """Read and validate a CSV or Parquet measurement table (``partial``: a campaign's
    readings so far, see :func:`validate_table`). ``ignore_sigma``: a sigma column is left
    out before it is checked (a column of zeros is then no error), and the table's notes
    say so (:data:`SIGMA_LEFT_OUT`).

    CSV: UTF-8 text (a byte-order mark is allowed), a header line, commas between fields,
    ``.`` as decimal point, ``#`` starts a comment. Every row must have as many fields as
    the header. Raises :class:`DataError` with one line for anything else.
    """
    if isinstance(path, pd.DataFrame):
        _fail("read_measurements reads a file; for a DataFrame use validate_table(df) "
              "(or pass the DataFrame to irreflect.fit directly)")
    if not isinstance(path, str | os.PathLike):
        _fail(f"expected a path to a CSV or Parquet table, found {type(path).__name__}")
    path = find_bundled(path, "table") or Path(path)
    if not path.exists():
        _fail(f"{path}: no such file: expected a CSV or Parquet measurement table"
              + _bundled_hint(path, "table"))
    if path.is_dir():
        _fail(f"{path}: is a folder; expected a CSV or Parquet measurement table")
    suffix = path.suffix.lower()
    if path.exists() and suffix not in _SUFFIXES:
        _fail(f"{path}: unknown file type '{suffix}': expected .csv or .parquet")
    try:
        raw = read_bytes(path, str(path), _EXPECTED, MAX_FILE_BYTES, _SUBSAMPLE)
    except DataError:
        raise
    except IrreflectError as exc:  # the reader's one line, as the table's DataError
        raise DataError(str(exc)) from None
    if suffix not in _SUFFIXES:
        _fail(f"{path}: unknown file type '{suffix}': expected .csv or .parquet")
    if suffix in (".parquet", ".pq"):
        df = _read_parquet(path, raw)
        lines = None
    else:
        df, lines = _read_csv(path, raw)
    dropped = ignore_sigma and "sigma" in df.columns
    if dropped:
        df = df.drop(columns=["sigma"])
    meas = validate_table(df, str(path), average_duplicates=average_duplicates,
                          partial=partial, name=path.stem, _row_lines=lines)
    if dropped:
        meas = replace(meas, notes=meas.notes + (SIGMA_LEFT_OUT,))
    return meas


_EXPECTED = "a CSV or Parquet measurement table"
_SUBSAMPLE = "subsample the table"
#: Parquet columns are decoded into at most this many bytes in all (the file itself is at
#: most MAX_FILE_BYTES; compressed, repetitive text can decode to gigabytes).
MAX_DECODED_BYTES = 512 * 2**20


def _read_parquet(path: Path, raw: bytes) -> pd.DataFrame:
    """The columns irreflect reads from a Parquet file, decoded within
    :data:`MAX_DECODED_BYTES` (counted on what is decoded, batch by batch, not on what
    the file declares)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(pa.BufferReader(raw))
        names = pf.schema_arrow.names
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            _fail(f"{path}: column '{dup[0]}' appears more than once: keep one, or rename "
                  "the others")
        if pf.metadata.num_rows > MAX_TABLE_ROWS:
            _fail(f"{path}: {pf.metadata.num_rows} rows is more than irreflect reads "
                  f"({MAX_TABLE_ROWS}): subsample the table")
        wanted = [n for n in names if str(n).strip() in REQUIRED + OPTIONAL]
        if len(wanted) < len(REQUIRED):  # the column check names what is missing
            return pd.DataFrame(columns=names)
        text = [n for n in wanted if _is_text(pf.schema_arrow.field(n).type)]
        if text:  # text read as dictionaries: counted value by value before decoding
            pf = pq.ParquetFile(pa.BufferReader(raw), read_dictionary=text)
        batches, decoded = [], 0
        for batch in pf.iter_batches(batch_size=4096, columns=wanted):
            decoded += _decoded_size(batch)
            if decoded > MAX_DECODED_BYTES:
                _fail(f"{path}: its columns decode to more than "
                      f"{MAX_DECODED_BYTES // 2**20} MB (long or many text values), more "
                      "than irreflect reads: keep numbers in gamma_deg, theta_deg, power "
                      "and sigma, and a short material name")
            batches.append(batch)
        table = (pa.Table.from_batches(batches) if batches else
                 pf.schema_arrow.empty_table().select(wanted))
        for i, column in enumerate(table.columns):
            if pa.types.is_dictionary(column.type):
                table = table.set_column(i, table.field(i).name,
                                         column.cast(column.type.value_type))
        return table.to_pandas()
    except (OSError, pa.ArrowException, ValueError, TypeError, IndexError) as exc:
        if isinstance(exc, DataError):
            raise
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        _fail(f"{path}: cannot be read as Parquet ({first}): write it again with pandas or "
              "pyarrow, or export the table as CSV")


def _is_text(kind) -> bool:
    import pyarrow as pa

    return (pa.types.is_string(kind) or pa.types.is_large_string(kind)
            or pa.types.is_binary(kind) or pa.types.is_large_binary(kind))


def _decoded_size(batch) -> int:
    """Bytes a record batch takes once decoded to pandas: dictionary-encoded text counted
    value by value (its dictionary is shared, its expansion is not)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    total = 0
    for column in batch.columns:
        if pa.types.is_dictionary(column.type):
            lengths = pc.binary_length(column.dictionary.cast(pa.large_binary()))
            per_row = pc.take(lengths, column.indices)
            total += int(pc.sum(per_row).as_py() or 0) + 64 * len(column)
        else:
            total += column.nbytes
    return total


def _decode(raw: bytes, path: Path) -> str:
    """The file's text, or a one-line error saying which encoding it seems to have."""
    head = raw[:4096]
    if head.startswith(b"PAR1"):
        _fail(f"{path}: the file is Parquet, not CSV: rename it to end in .parquet")
    if head.startswith((b"PK\x03\x04", b"\xd0\xcf\x11\xe0")):
        _fail(f"{path}: the file is a spreadsheet or archive (binary), not CSV text: export "
              "it as 'CSV UTF-8' (comma-delimited)")
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or _looks_utf16(head):
        _fail(f"{path}: the file is UTF-16 (or UTF-32) text; expected UTF-8: save it as "
              "'CSV UTF-8' (comma-delimited)")
    if b"\x00" in head:
        _fail(f"{path}: the file is binary, not CSV text: expected a UTF-8 text table with "
              "the header gamma_deg,theta_deg,power")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        _fail(f"{path}: the file is not UTF-8 text (byte 0x{raw[exc.start]:02x} on line "
              f"{line}; Latin-1 or Windows-1252?): save it as UTF-8 ('CSV UTF-8' in a "
              "spreadsheet)")
    control = sum(text[:4096].count(c) for c in map(chr, (*range(1, 9), 11, 12, *range(14, 32))))
    if control > 8:
        _fail(f"{path}: the file has {control} control characters in its first lines: it is "
              "not a CSV text table (expected UTF-8 text with the header gamma_deg,theta_deg,power)")
    return text


def _looks_utf16(head: bytes) -> bool:
    """UTF-16/32 text without a byte-order mark: decodes to printable text."""
    if b"\x00" not in head:
        return False
    for codec in ("utf-16-le", "utf-16-be", "utf-32-le", "utf-32-be"):
        try:
            text = head[: len(head) // 4 * 4].decode(codec)
        except UnicodeDecodeError:
            continue
        printable = sum(c.isprintable() or c in "\r\n\t" for c in text)
        if text and printable >= 0.95 * len(text) and any(c.isalnum() for c in text):
            return True
    return False


def _read_csv(path: Path, raw: bytes) -> tuple[pd.DataFrame, list[int]]:
    """Parse a CSV strictly: every row has as many fields as the header (pandas would take
    an extra leading field as the index and shift every column silently)."""
    text = _decode(raw, path)
    numbers, kept = [], []
    for no, line in enumerate(text.splitlines(), 1):
        cut = line.find("#")
        if cut >= 0:
            line = line[:cut]
        if line.strip():
            numbers.append(no)
            kept.append(line)
    if not kept:
        _fail(f"{path}: the file is empty: expected a header line gamma_deg,theta_deg,power "
              "and one line per measurement")
    if len(kept) - 1 > MAX_TABLE_ROWS:
        _fail(f"{path}: {len(kept) - 1} rows is more than irreflect reads ({MAX_TABLE_ROWS}): "
              "subsample the table")
    try:
        records = list(csv.reader(kept, skipinitialspace=True))
    except csv.Error as exc:
        _fail(f"{path}: cannot be read as CSV ({exc}): check the quotes")
    header = [h.strip() for h in records[0]]
    width = len(header)
    if width == 1 and _separator_hint(header[0]):
        _fail(f"{path}: the header '{_clip(header[0])}' is one field{_separator_hint(header[0])}")
    for i, fields in enumerate(records[1:]):
        if len(fields) != width:
            more = len(fields) > width
            hint = ("remove the extra field (or quote a value that contains a comma; a decimal "
                    "comma must be '.')" if more else "fill in the missing value or remove the row")
            _fail(f"{path}: line {numbers[i + 1]} (data row {i + 1}) has {len(fields)} fields, "
                  f"the header {width}: {hint}")
    columns = list(zip(*records[1:], strict=True)) if len(records) > 1 else [()] * width
    data = {i: pd.Series(col, dtype=object) for i, col in enumerate(columns)}
    df = pd.DataFrame(data)
    if df.shape[1] != width:  # no data rows
        df = pd.DataFrame(columns=range(width))
    df.columns = header
    return df, numbers[1:]


def write_measurements(meas: Measurements, path) -> Path:
    """Write a table as CSV or Parquet (by extension), atomically and losslessly."""
    if isinstance(meas, pd.DataFrame):
        meas = validate_table(meas)
    if not isinstance(meas, Measurements):
        _fail(f"write_measurements expects Measurements (or a DataFrame); found "
              f"{type(meas).__name__}")
    if not isinstance(path, str | os.PathLike):
        _fail(f"expected a file path ending in .csv or .parquet, found {type(path).__name__}")
    path = Path(path)
    if path.is_dir():
        _fail(f"{path}: is a folder; expected a file path ending in .csv or .parquet")
    if path.suffix.lower() not in (".csv", ".parquet", ".pq"):
        _fail(f"{path}: expected a file name ending in .csv or .parquet; found "
              f"'{path.suffix or 'no suffix'}'")
    df = meas.to_frame()
    with atomic_path(path) as tmp:
        if path.suffix.lower() in (".parquet", ".pq"):
            df.to_parquet(tmp, index=False)
        else:
            df.to_csv(tmp, index=False, float_format=None)
    return path


def as_measurements(obj, **kwargs) -> Measurements:
    """Accept Measurements, a DataFrame or a path."""
    if isinstance(obj, Measurements):
        return obj
    if isinstance(obj, pd.DataFrame):
        return validate_table(obj, "table", **kwargs)
    if isinstance(obj, str | os.PathLike):
        return read_measurements(obj, **kwargs)
    _fail(f"expected a measurement table (path, DataFrame or Measurements), found {type(obj).__name__}")


def check_enough_points(n_points: int, model, source: str = "table") -> None:
    """Refuse a fit with no degree of freedom left: ``n_points <= n_params``."""
    k = model.n_params
    if n_points <= k:
        _fail(
            f"{source}: found {n_points} points while at least {k + 1} are needed to fit the "
            f"{k} parameters of '{model.name}' with a degree of freedom left: measure more "
            "points or choose a model with fewer parameters"
        )


# ----------------------------------------------------------------------------- datasets
BUNDLED = ("terrazzo", "plasterboard", "foam_board")
#: The bundled example scenes (``irreflect room office``).
BUNDLED_SCENES = ("office",)

_RECONSTRUCTION = ("reconstruction of the paper's {name}, not a measurement: its Table 3 "
                   "model on its sampling plan plus seeded Gaussian noise")


@dataclass(frozen=True)
class BundledFile:
    """One file shipped with irreflect: its name (what commands accept in place of a path),
    kind, where it came from, and where it lies in the installed package."""

    name: str
    kind: str  # "table", "scene", "material", "paper table", "readme"
    origin: str
    path: Path
    points: int | None = None


def bundled_files() -> list[BundledFile]:
    """Every dataset, scene, material file and paper table shipped inside the package,
    with its origin and installed path (``irreflect datasets`` prints them)."""
    from .paper import PAPER_SOURCE, PAPER_TABLES, paper_tables_dir

    root = bundled_dir()
    out = []
    for name in BUNDLED:
        path = root / f"{name}.csv"
        with open(path, encoding="utf-8") as fh:
            rows = sum(1 for line in fh if line.strip() and not line.startswith("#")) - 1
        out.append(BundledFile(name, "table",
                               _RECONSTRUCTION.format(name=name.replace("_", " ")), path, rows))
    for name in BUNDLED_SCENES:
        out.append(BundledFile(name, "scene", "example room: Barry et al.'s (1993) configuration "
                               "A geometry with the three materials fitted from the "
                               "reconstructions, a desk, three receivers and a receiver grid",
                               root / "rooms" / f"{name}.toml"))
    for name in BUNDLED:
        out.append(BundledFile(f"rooms/{name}.json", "material",
                               f"two-lobe fit of the {name} reconstruction (irreflect fit "
                               "--save), used by the office scene", root / "rooms" / f"{name}.json"))
    papers = paper_tables_dir()
    for file, (table, what) in PAPER_TABLES.items():
        out.append(BundledFile(file.removesuffix(".csv"), "paper table",
                               f"the paper's {table} ({what}), as published in "
                               f"{PAPER_SOURCE}", papers / file))
    return out


def find_bundled(name, kind: str = "table") -> Path | None:
    """The installed path of a bundled file of ``kind`` ("table" or "scene") named ``name``
    (``terrazzo``, ``terrazzo.csv``; ``office``, ``office.toml``), or None. A file that
    exists at ``name`` always wins: names are looked up only when there is no such file."""
    if not isinstance(name, str | os.PathLike):
        return None
    text = str(name)
    if Path(text).exists() or os.sep in text or "/" in text:
        return None
    names, suffix = ((BUNDLED, ".csv") if kind == "table" else (BUNDLED_SCENES, ".toml"))
    stem = text[: -len(suffix)] if text.endswith(suffix) else text
    if stem not in names:
        return None
    folder = bundled_dir() if kind == "table" else bundled_dir() / "rooms"
    return folder / f"{stem}{suffix}"


def _bundled_hint(path: Path, kind: str) -> str:
    """What to write instead of a missing path that names a bundled file."""
    names, suffix = ((BUNDLED, ".csv") if kind == "table" else (BUNDLED_SCENES, ".toml"))
    stem = path.name[: -len(suffix)] if path.name.endswith(suffix) else path.name
    if stem in names:
        return (f"; the bundled '{stem}' is reachable by name: write '{stem}' instead of a "
                "path ('irreflect datasets' lists what ships with irreflect)")
    close = ([] if os.sep in str(path) or "/" in str(path) else
             difflib.get_close_matches(stem.casefold(), names, n=1))
    return (f" (or the name of a bundled {'dataset' if kind == 'table' else 'scene'}: "
            f"{', '.join(names)}; 'irreflect datasets' lists them)"
            + (f". Did you mean '{close[0]}'?" if close else ""))


def resolve_scene(scene) -> Path:
    """A scene file as given, or a bundled scene by name (``office``); a missing file is a
    one-line error naming the bundled scenes."""
    found = find_bundled(scene, "scene")
    if found is not None:
        return found
    path = Path(scene)
    if not path.exists():
        _fail(f"{path}: no such file: expected a scene (TOML)" + _bundled_hint(path, "scene"))
    return path


def bundled_dir() -> Path:
    """Folder of the bundled (reconstructed) datasets: ``$IRREFLECT_DATASETS``, else the
    package data ``irreflect/datasets`` (found through :mod:`importlib.resources`, so an
    installed package has them too; ``datasets/`` at the top of a checkout links there)."""
    env = os.environ.get("IRREFLECT_DATASETS")
    return Path(env) if env else Path(str(resources.files("irreflect") / "datasets"))


def real_data_dir() -> Path | None:
    """The real measured data beside the checkout (see :func:`irreflect.paper.real_data_dir`)."""

    return _real()


def load_bundled(name: str) -> Measurements:
    """One of the bundled reconstructed datasets by name (``terrazzo``, ``plasterboard``, ``foam_board``)."""

    if name not in BUNDLED:
        raise unknown_name("bundled dataset", name, BUNDLED)
    return read_measurements(bundled_dir() / f"{name}.csv")


def real_datasets() -> dict[str, Path]:
    """Real measured tables found under :func:`real_data_dir`, by file stem."""
    root = real_data_dir()
    if root is None:
        return {}
    return {p.stem: p for p in sorted(root.rglob("*.csv"))}


def header_only(path: Path) -> bool:
    """True when the table at ``path`` has column names and no rows (the names are checked):
    a campaign's first table (`irreflect next`)."""
    if path.suffix.lower() in (".parquet", ".pq"):  # read within the table's limit
        df = _read_parquet(path, read_bytes(path, str(path), "a CSV or Parquet measurement "
                                            "table", MAX_FILE_BYTES))
        if len(df):
            return False
        _check_columns(df, str(path))
        return True
    if path.stat().st_size > 65536:
        return False
    text = _decode(read_bytes(path, str(path), "a CSV or Parquet measurement table", 65536),
                   path)
    lines = [line.split("#", 1)[0] for line in text.splitlines()]
    lines = [line for line in lines if line.strip()]
    if len(lines) != 1:
        return False
    header = [h.strip() for h in next(csv.reader(lines, skipinitialspace=True))]
    _check_columns(pd.DataFrame(columns=header), str(path))
    return True
