"""Reading the readings of a campaign: a measurement table that may hold only its header.

A campaign starts with nothing measured, so ``irreflect next`` accepts a table whose only
line is the header ``gamma_deg,theta_deg,power`` (or a Parquet file without rows); every
other table goes through :func:`irreflect.data.read_measurements` and its checks, as the
readings of a campaign (``partial``: they may all be 0 so far, and one may be negative
noise).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..data import Measurements, header_only, read_measurements
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
