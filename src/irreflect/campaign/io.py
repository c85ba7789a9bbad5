"""Reading the readings of a campaign: a measurement table that may hold only its header.

A campaign starts with nothing measured, so ``irreflect next`` accepts a table whose only
line is the header ``gamma_deg,theta_deg,power`` (or a Parquet file without rows); every
other table goes through :func:`irreflect.data.read_measurements` and its checks.
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from .._inputs import read_bytes
from ..data import (
    MAX_FILE_BYTES,
    Measurements,
    _check_columns,
    _decode,
    _read_parquet,
    read_measurements,
)
from ..errors import DataError


def read_readings(path, *, average_duplicates: bool = False,
                  max_rows: int | None = None) -> Measurements | None:
    """The readings of ``path`` (CSV or Parquet), or None when it holds only a header (its
    column names are still checked). More than ``max_rows`` readings are refused."""
    if not isinstance(path, str | os.PathLike):
        raise DataError(f"expected a path to a CSV or Parquet table, found {type(path).__name__}")
    p = Path(path)
    if p.is_file() and _header_only(p):
        return None
    meas = read_measurements(p, average_duplicates=average_duplicates)
    if max_rows is not None and meas.n_points > max_rows:
        raise DataError(f"{p}: {meas.n_points} readings is more than a campaign takes "
                        f"({max_rows}): this is a dense scan; replay campaigns on it with "
                        "'irreflect campaign' instead")
    return meas


def _header_only(path: Path) -> bool:
    """True when the table has column names and no rows (the names are checked)."""
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
    import csv

    header = [h.strip() for h in next(csv.reader(lines, skipinitialspace=True))]
    _check_columns(pd.DataFrame(columns=header), str(path))
    return True
