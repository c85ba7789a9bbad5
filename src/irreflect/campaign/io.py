"""Reading the readings of a campaign: a measurement table that may hold only its header.

A campaign starts with nothing measured, so ``irreflect next`` accepts a table whose only
line is the header ``gamma_deg,theta_deg,power`` (or a Parquet file without rows); every
other table goes through :func:`irreflect.data.read_measurements` and its checks, as the
readings of a campaign (``partial``: they may all be 0 so far, and one may be negative
noise).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from ..data import Measurements, header_only, read_measurements, validate_table
from ..errors import DataError


def read_readings(path, *, average_duplicates: bool = False,
                  max_rows: int | None = None) -> Measurements | None:
    """The readings of ``path`` (CSV or Parquet), or None when it holds only a header (its
    column names are still checked). More than ``max_rows`` readings are refused."""
    if not isinstance(path, str | os.PathLike):
        raise DataError(f"expected a path to a CSV or Parquet table, found {type(path).__name__}")
    p = Path(path)
    if p.is_file() and header_only(p):
        return None
    meas = read_measurements(p, average_duplicates=average_duplicates, partial=True)
    if max_rows is not None and meas.n_points > max_rows:
        raise DataError(f"{p}: {meas.n_points} readings is more than a campaign takes "
                        f"({max_rows}): this is a dense scan; replay campaigns on it with "
                        "'irreflect campaign' instead")
    return meas


def _not_rows(rows) -> str:
    """Why ``rows`` are not (gamma, theta, power[, sigma]) rows of numbers: the first row of
    another length, or the first value that is not a number ("found list" said neither)."""
    head = "readings must be a table or (gamma, theta, power[, sigma]) rows of numbers"
    if isinstance(rows, Mapping):
        return (f"{head}; found a dict: pass pandas.DataFrame(...) of it, with columns "
                "gamma_deg, theta_deg, power[, sigma]")
    if isinstance(rows, pd.Series):  # a table's row (df.iloc[i]): its labels name the values
        return (f"{head}; found a pandas Series (one row of a table): pass a table, "
                "df.iloc[[i]] rather than df.iloc[i], or series.to_frame().T")
    try:
        items = list(rows)
    except TypeError:
        return f"{head}; found {type(rows).__name__}"
    lengths = set()
    for i, row in enumerate(items, 1):
        if isinstance(row, Mapping | pd.Series):
            # records: iterating one gave its keys ("found 'gamma_deg'"); a table's rows
            # (iterrows) were read by position, whatever their labels' order
            what = "dict" if isinstance(row, Mapping) else "pandas Series"
            return (f"{head}; found a {what} as reading {i}: pass pandas.DataFrame(rows) of "
                    "them, each with keys gamma_deg, theta_deg, power[, sigma]")
        try:
            values = list(row)
        except TypeError:
            return (f"{head}; found {row!r} as reading {i}, not a row: pass one tuple per "
                    "reading, e.g. [(-20, 20, 0.1)]")
        lengths.add(len(values))
        for value in values:
            try:
                float(value)
            except (TypeError, ValueError):
                return (f"{head}; found {value!r} in reading {i}: give the number alone (power "
                        "in any one unit, without the unit's name)")
        if len(lengths) > 1:
            return (f"{head}; found reading {i} with {len(values)} value(s) after rows of "
                    f"{len(items[0])}: give every reading the same values")
    return f"{head}; found {type(rows).__name__}"


def as_rows(rows) -> pd.DataFrame:
    """Readings as :meth:`irreflect.campaign.Campaign.add` takes them (a table, a
    :class:`~irreflect.data.Measurements`, a path as :func:`read_readings` reads it, or
    (gamma, theta, power[, sigma]) rows of numbers) as a DataFrame ``gamma_deg, theta_deg,
    power[, sigma]``; anything else is refused in one line (:func:`_not_rows`)."""
    if rows is None:
        return pd.DataFrame(columns=["gamma_deg", "theta_deg", "power"])
    if isinstance(rows, Measurements):
        frame = rows.to_frame()
    elif isinstance(rows, pd.DataFrame):
        frame = rows
    elif isinstance(rows, str | os.PathLike):
        # as ``irreflect next`` reads MEASURED.csv: a header alone is nothing measured yet
        # (it was refused, "the table has no rows"), and the readings so far may all be 0
        meas = read_readings(Path(rows))
        if meas is None:
            return pd.DataFrame(columns=["gamma_deg", "theta_deg", "power"])
        frame = meas.to_frame()
    elif isinstance(rows, Mapping | pd.Series):
        raise DataError(_not_rows(rows))
    else:
        try:
            items = list(rows)
        except TypeError as exc:
            raise DataError(_not_rows(rows)) from exc
        try:
            if any(isinstance(row, Mapping | pd.Series) for row in items):
                raise TypeError("rows with labels, read by position")
            arr = np.asarray(items, float)
        except (TypeError, ValueError) as exc:
            raise DataError(_not_rows(items)) from exc
        if arr.size == 0:
            return pd.DataFrame(columns=["gamma_deg", "theta_deg", "power"])
        if arr.ndim == 1 and arr.size in (3, 4):
            raise DataError(f"readings must be (gamma, theta, power[, sigma]) rows; found one "
                            f"row of {arr.size} numbers, not in a list: pass "
                            f"[{tuple(float(x) for x in arr)}]")
        if arr.ndim != 2 or arr.shape[1] not in (3, 4):
            raise DataError(f"readings must be (gamma, theta, power[, sigma]) rows; found "
                            f"shape {arr.shape}")
        cols = ["gamma_deg", "theta_deg", "power", "sigma"][: arr.shape[1]]
        frame = pd.DataFrame(arr, columns=cols)
    if not len(frame):
        return pd.DataFrame(columns=["gamma_deg", "theta_deg", "power"])
    meas = validate_table(frame.copy(), "readings", partial=True)
    return meas.to_frame().drop(columns=["material"], errors="ignore")
