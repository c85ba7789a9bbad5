"""Measurement tables: read, validate, write; the bundled and the real datasets.

A table has columns ``gamma_deg, theta_deg, power`` and optionally ``sigma`` (1-sigma
uncertainty of power) and ``material``; CSV or Parquet. Angles in degrees, in the
paper's convention: gamma negative on the source side, mirror direction theta = -gamma.

Every check raises :class:`~irreflect.errors.DataError` with one line saying what was
expected, what was found and how to fix it.
"""

from __future__ import annotations

import difflib
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ._atomic import atomic_path
from .errors import DataError

REQUIRED = ("gamma_deg", "theta_deg", "power")
OPTIONAL = ("sigma", "material")
#: A negative power is accepted as noise around zero only down to this fraction of the
#: table's maximum power (or 4 sigma, when sigma is given).
NEGATIVE_POWER_TOLERANCE = 0.02


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


def _check_columns(df: pd.DataFrame, source: str) -> pd.DataFrame:
    cols = [str(c) for c in df.columns]
    stripped = {c: c.strip() for c in cols}
    df = df.rename(columns=stripped)
    cols = list(df.columns)
    for need in REQUIRED:
        if need in cols:
            continue
        candidates = [c for c in cols if c not in REQUIRED + OPTIONAL]
        lower = {c.lower(): c for c in candidates}
        close = difflib.get_close_matches(need, candidates, n=1, cutoff=0.5)
        if need in lower:
            close = [lower[need]]
        hint = f"; found '{close[0]}': rename it to '{need}'" if close else ""
        _fail(
            f"{source}: missing column '{need}': expected columns gamma_deg, theta_deg, power "
            f"(optional sigma, material), found {', '.join(cols) or 'none'}{hint}"
        )
    return df


def _numeric(df: pd.DataFrame, col: str, source: str) -> np.ndarray:
    raw = df[col]
    values = pd.to_numeric(raw, errors="coerce")
    bad = values.isna() & raw.notna() & (raw.astype(str).str.strip().str.lower() != "nan")
    if bad.any():
        i = int(np.nonzero(bad.to_numpy())[0][0])
        _fail(
            f"{source}: column '{col}' must be numeric; found '{raw.iloc[i]}' in data row {i + 1} "
            f"(line {i + 2} of a CSV with a header): fix or remove that row"
        )
    arr = values.to_numpy(dtype=float)
    nonfinite = ~np.isfinite(arr)
    if nonfinite.any():
        i = int(np.nonzero(nonfinite)[0][0])
        _fail(
            f"{source}: column '{col}' has {int(nonfinite.sum())} empty, NaN or infinite value(s), "
            f"first in data row {i + 1} (line {i + 2}): measure it again or remove the row"
        )
    return arr


def validate_table(df: pd.DataFrame, source: str = "table", *,
                   average_duplicates: bool = False, name: str | None = None) -> Measurements:
    """Check a table and convert it to :class:`Measurements` (see the module docstring)."""
    if not isinstance(df, pd.DataFrame):
        _fail(f"{source}: expected a table (pandas DataFrame), found {type(df).__name__}")
    df = _check_columns(df, source)
    if len(df) == 0:
        _fail(f"{source}: the table has no rows: expected at least one measurement")
    gamma = _numeric(df, "gamma_deg", source)
    theta = _numeric(df, "theta_deg", source)
    power = _numeric(df, "power", source)
    sigma = _numeric(df, "sigma", source) if "sigma" in df.columns else None
    notes = []
    for col, arr in (("gamma_deg", gamma), ("theta_deg", theta)):
        out = np.abs(arr) >= 90
        if out.any():
            i = int(np.nonzero(out)[0][0])
            _fail(
                f"{source}: {col} must lie strictly between -90 and 90 degrees; found {arr[i]:g} "
                f"in data row {i + 1}: angles are in degrees from the surface normal"
            )
    if sigma is not None and np.any(sigma < 0):
        i = int(np.nonzero(sigma < 0)[0][0])
        _fail(
            f"{source}: sigma is a 1-sigma uncertainty and must be >= 0; found {sigma[i]:g} "
            f"in data row {i + 1}"
        )
    positive, negative = np.any(gamma > 0), np.any(gamma < 0)
    if positive and negative:
        _fail(
            f"{source}: gamma_deg mixes positive and negative angles of incidence, which is "
            "ambiguous: use the paper's convention (all <= 0, source side) or magnitudes (all >= 0)"
        )
    if positive:
        gamma = -gamma
        note = (f"{source}: all gamma_deg >= 0, read as magnitudes (gamma = -|gamma|) with the "
                "mirror direction on the positive-theta side")
        notes.append(note)
    material = None
    if "material" in df.columns:
        mats = df["material"].dropna().astype(str).unique()
        material = mats[0] if len(mats) == 1 else (", ".join(mats) if len(mats) else None)
    # duplicated (gamma, theta)
    key = pd.DataFrame({"g": gamma, "t": theta})
    dup = key.duplicated(keep=False).to_numpy()
    if dup.any():
        if not average_duplicates:
            i = int(np.nonzero(dup)[0][0])
            _fail(
                f"{source}: {int(key.duplicated().sum())} duplicated (gamma_deg, theta_deg) rows, "
                f"first ({gamma[i]:g}, {theta[i]:g}) at data row {i + 1}: remove them or pass "
                "--average-duplicates to average their power"
            )
        frame = pd.DataFrame({"g": gamma, "t": theta, "p": power})
        if sigma is not None:
            frame["s2"] = sigma**2
        grouped = frame.groupby(["g", "t"], sort=False)
        agg = grouped.agg(p=("p", "mean"), k=("p", "size"))
        if sigma is not None:
            agg["s"] = np.sqrt(grouped["s2"].sum()) / agg["k"]
        n_merged = int(len(frame) - len(agg))
        gamma = agg.index.get_level_values(0).to_numpy(float)
        theta = agg.index.get_level_values(1).to_numpy(float)
        power = agg["p"].to_numpy(float)
        sigma = agg["s"].to_numpy(float) if sigma is not None else None
        notes.append(f"{source}: averaged {n_merged} duplicated (gamma, theta) row(s)")
    # negative powers: only small noise around zero
    neg = power < 0
    if neg.any():
        limit = NEGATIVE_POWER_TOLERANCE * max(np.max(np.abs(power)), 1e-300)
        if sigma is not None:
            limit = np.maximum(limit, 4 * sigma)
        too_neg = power < -np.broadcast_to(limit, power.shape)
        if too_neg.any():
            i = int(np.nonzero(too_neg)[0][0])
            _fail(
                f"{source}: power must be >= 0 up to noise; found {power[i]:g} at data row {i + 1}, "
                f"below the noise allowance {-np.broadcast_to(limit, power.shape)[i]:g}: check the "
                "detector offset or the sign of the column"
            )
        notes.append(f"{source}: {int(neg.sum())} slightly negative power value(s) kept as noise "
                     "around zero")
    for note in notes:  # said once per table; the CLI prints them as "irreflect: note: ..."
        warnings.warn(note, DataNotice, stacklevel=3)
    return Measurements(
        gamma_deg=gamma, theta_deg=theta, power=power, sigma=sigma, material=material,
        name=name or Path(str(source)).stem, notes=tuple(notes),
    )


def read_measurements(path, *, average_duplicates: bool = False) -> Measurements:
    """Read and validate a CSV or Parquet measurement table."""
    path = Path(path)
    if not path.exists():
        _fail(f"{path}: no such file: expected a CSV or Parquet measurement table")
    suffix = path.suffix.lower()
    try:
        if suffix in (".parquet", ".pq"):
            df = pd.read_parquet(path)
        elif suffix in (".csv", ".txt", ""):
            df = pd.read_csv(path, dtype=str, comment="#", skipinitialspace=True,
                             keep_default_na=False, na_values=["", "nan", "NaN", "NA"])
        else:
            _fail(f"{path}: unknown file type '{suffix}': expected .csv or .parquet")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        _fail(f"{path}: cannot be read as a {suffix.lstrip('.') or 'CSV'} table ({first})")
    except Exception as exc:  # pyarrow raises its own error types for corrupt files
        if type(exc).__module__.startswith("pyarrow"):
            _fail(f"{path}: cannot be read as Parquet ({str(exc).splitlines()[0]})")
        raise
    return validate_table(df, str(path), average_duplicates=average_duplicates, name=path.stem)


def write_measurements(meas: Measurements, path) -> Path:
    """Write a table as CSV or Parquet (by extension), atomically and losslessly."""
    path = Path(path)
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


def project_root() -> Path:
    return Path(__file__).resolve().parents[2]


def bundled_dir() -> Path:
    """Folder of the bundled (reconstructed) datasets: ``$IRREFLECT_DATASETS`` or ``datasets/``."""
    env = os.environ.get("IRREFLECT_DATASETS")
    return Path(env) if env else project_root() / "datasets"


def real_data_dir() -> Path | None:
    """``../shared/datasets/real`` beside the checkout (or ``$IRREFLECT_REAL_DATA``), if present."""
    env = os.environ.get("IRREFLECT_REAL_DATA")
    candidates = [Path(env)] if env else []
    root = project_root()
    candidates += [root.parent / "shared" / "datasets" / "real",
                   root.parent.parent / "shared" / "datasets" / "real"]
    for c in candidates:
        if c.is_dir():
            return c
    return None


def load_bundled(name: str) -> Measurements:
    """One of the bundled reconstructed datasets by name (``terrazzo``, ``plasterboard``, ``foam_board``)."""
    from .errors import unknown_name

    if name not in BUNDLED:
        raise unknown_name("bundled dataset", name, BUNDLED)
    return read_measurements(bundled_dir() / f"{name}.csv")


def real_datasets() -> dict[str, Path]:
    """Real measured tables found under :func:`real_data_dir`, by file stem."""
    root = real_data_dir()
    if root is None:
        return {}
    return {p.stem: p for p in sorted(root.rglob("*.csv"))}
