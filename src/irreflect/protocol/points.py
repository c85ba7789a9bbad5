"""The paper's 12 protocol points in a dense dataset: which points (Table 1, or the same
rule on the dataset's own angles), snapped to distinct measured points, as a mask.

One implementation, used by the selection (Method 12 of Table 5), the protocol evaluation
and the report.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pandas as pd

from .. import metrics
from ..data import Measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import fit
from ..paper import TABLE1
from .advice import Cause, ProtocolVerdict, assess, judge
from .evaluate import paper_protocol_for, sample_protocol
from .export import as_protocol


def paper_protocol_points(meas: Measurements | None = None) -> pd.DataFrame:
    """The paper's 12 protocol points (section 4.3, Table 1) as ``gamma_deg, theta_deg``.

    With a dense dataset, the protocol is the one :func:`.evaluate.paper_protocol_for`
    builds for that dataset: Table 1 (gammas -20/-40/-60, receivers within +-70 deg) when the dataset has those angles of
    incidence, else the same rule on three of its own angles of incidence and its receiver
    range. Otherwise Table 1 itself (:data:`irreflect.paper.TABLE1`).
    """
    if meas is not None:
        try:
            return paper_protocol_for(meas).to_frame()[["gamma_deg", "theta_deg"]]
        except IrreflectError:
            pass  # no triple of the dataset's gammas can carry the protocol: use Table 1
    return pd.DataFrame(TABLE1, columns=["gamma_deg", "theta_deg"]).astype(float)


def snap_points(meas: Measurements, points) -> pd.DataFrame:
    """Snap requested (gamma, theta) points (degrees) to the nearest measured points.

    Nearest in the (gamma, theta) plane, Euclidean in degrees; a measured point is used
    once (a second request for it goes to its next nearest free point). Returns a table
    with the requested and the snapped angles, the distance (deg) and the row index.
    """
    pts = as_points(points)
    if len(pts) > meas.n_points:
        raise IrreflectError(
            f"cannot snap {len(pts)} protocol points to the {meas.n_points} measured points of "
            f"{meas.name}: each needs its own measured point; measure at least {len(pts)} "
            "points or pass fewer protocol points"
        )
    taken = np.zeros(meas.n_points, bool)
    rows = []
    for g, t in pts:
        dist = np.hypot(meas.gamma_deg - g, meas.theta_deg - t)
        dist = np.where(taken, np.inf, dist)
        # of measured points as near, the one of lowest (gamma, theta): not the first in
        # the table's rows, so that the same scan in another row order snaps alike
        near = np.flatnonzero(dist == dist.min())
        i = int(near[np.lexsort((meas.theta_deg[near], meas.gamma_deg[near]))[0]])
        taken[i] = True
        rows.append({"gamma_requested": g, "theta_requested": t,
                     "gamma_deg": meas.gamma_deg[i], "theta_deg": meas.theta_deg[i],
                     "distance_deg": float(dist[i]), "index": i})
    return pd.DataFrame(rows)


#: The farthest a protocol point may be moved along theta to a measured point, deg: the
#: protocol evaluation's default tolerance (:func:`.evaluate.sample_protocol`).
SNAP_LIMIT_DEG = 5.0


def check_snapped(meas: Measurements, snapped: pd.DataFrame,
                  what: str = "the paper's 12-point protocol") -> None:
    """Refuse snapped protocol points (:func:`snap_points`) that stand for other settings:
    a point moved to another angle of incidence, or more than :data:`SNAP_LIMIT_DEG` along
    theta. The protocol evaluation refuses the same table (it keeps each point's angle of
    incidence and interpolates within 5 deg), so a score of such points would describe
    another protocol."""
    dg = np.abs(snapped["gamma_deg"] - snapped["gamma_requested"]).to_numpy(float)
    dt = np.abs(snapped["theta_deg"] - snapped["theta_requested"]).to_numpy(float)
    bad = (dg > 1e-6) | (dt > SNAP_LIMIT_DEG + 1e-9)
    if not bad.any():
        return
    worst = snapped[bad].sort_values("distance_deg").iloc[-1]
    raise IrreflectError(
        f"{meas.name} does not measure the angles of {what}: {int(bad.sum())} of its "
        f"{len(snapped)} points have no measured point at their angle of incidence within "
        f"{SNAP_LIMIT_DEG:g} deg of their receiver angle (the farthest, "
        f"({worst.gamma_requested:g}, {worst.theta_requested:g}), would move to "
        f"({worst.gamma_deg:g}, {worst.theta_deg:g}), {worst.distance_deg:.3g} deg away): not evaluated; "
        "a table with those angles of incidence and receivers every 10 deg or closer can "
        "score it")


def protocol_points_mask(meas: Measurements, points=None) -> np.ndarray:
    """Boolean mask (n,) of the measured points nearest to ``points`` (default: the paper's
    protocol, see :func:`paper_protocol_points`), each snapped to a distinct measured point
    (see :func:`snap_points`)."""
    return protocol_mask(meas, points)[0]


def as_points(points) -> np.ndarray:
    """``(m, 2)`` array of (gamma_deg, theta_deg) pairs from a frame or a sequence."""
    if isinstance(points, pd.DataFrame):
        missing = {"gamma_deg", "theta_deg"} - set(points.columns)
        if missing:
            raise IrreflectError(
                f"protocol points need columns gamma_deg, theta_deg; missing {sorted(missing)}"
            )
        return points[["gamma_deg", "theta_deg"]].to_numpy(float)
    try:
        arr = np.asarray(points, float)
    except (TypeError, ValueError):
        raise IrreflectError(
            f"protocol points must be (gamma_deg, theta_deg) pairs of numbers (degrees); "
            f"found {points!r:.60}: pass e.g. [(-20, 0), (-20, 20), ...] or a frame"
        ) from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise IrreflectError(
            f"protocol points must be (gamma_deg, theta_deg) pairs; found shape {arr.shape}"
        )
    return arr


def protocol_mask(meas: Measurements, points=None):
    """``(mask, snaps)``: the mask of :func:`protocol_points_mask` and the snaps that moved a
    point, as ``(gamma_requested, theta_requested, gamma_deg, theta_deg)`` tuples."""
    snapped = snap_points(meas, paper_protocol_points(meas) if points is None else points)
    check_snapped(meas, snapped)
    mask = np.zeros(meas.n_points, bool)
    mask[snapped["index"].to_numpy()] = True
    moved = snapped[snapped["distance_deg"] > 0]
    snaps = [(r.gamma_requested, r.theta_requested, r.gamma_deg, r.theta_deg)
             for r in moved.itertuples()]
    return mask, snaps


def assess_subset(meas: Measurements, points=None, reference=None, *, subset_fit=None,
                  model="two-lobe", seed: int = 0,
                  what: str = "the paper's 12-point protocol") -> ProtocolVerdict:
    """The verdict (:func:`.advice.assess`) of protocol points snapped to the measured
    points of a dense table, as the selection's Method 12 and the report's Table 2 score
    them: the model fitted on the snapped points (``subset_fit``, fitted with
    ``fit(meas.subset(mask), model, seed=seed)`` when not given), judged on all points
    against ``reference`` (the fit on all points; fitted when not given).

    ``points``: ``(gamma_deg, theta_deg)`` pairs or a frame (default: the paper's
    protocol, :func:`paper_protocol_points`).
    """
    snapped = snap_points(meas, paper_protocol_points(meas) if points is None else points)
    check_snapped(meas, snapped, what)
    mask = np.zeros(meas.n_points, bool)
    mask[snapped["index"].to_numpy()] = True
    with warnings.catch_warnings():  # the verdict reports what these fits' warnings say
        warnings.simplefilter("ignore", FitWarning)
        if subset_fit is None:
            subset_fit = fit(meas.subset(mask), model, seed=seed)
        if reference is None:
            reference = fit(meas, model, seed=seed)
    frame = pd.DataFrame({
        "gamma_deg": snapped["gamma_deg"].to_numpy(float),
        "theta_deg": snapped["theta_deg"].to_numpy(float),
        "source": np.where(snapped["distance_deg"] > 1e-9, "snapped", "measured"),
        "gap_deg": snapped["distance_deg"].to_numpy(float),
    })
    verdict = assess(meas, subset_fit, reference, frame, what=what)
    unstable = _placement_sensitivity(meas, points, snapped, verdict, reference, model, seed,
                                      what)
    if unstable is None:
        return verdict
    return replace(verdict, causes=(unstable,) + verdict.causes)


def _placement_sensitivity(meas, points, snapped, verdict, reference, model, seed,
                           what) -> Cause | None:
    """When some of the protocol's points are not measured in the table (snapped to
    measured points up to :data:`SNAP_LIMIT_DEG` away), the same protocol read as
    evaluate-protocol and the campaign's replay read it (interpolated along theta to its
    own angles): a verdict of another status is told as the first cause. On Cornell Krylon
    (a coarse grid) 9 of the paper's 12 points snapped 0.21-3.7 deg gave R^2 -171 against
    all points and 'PROTOCOL FAILS', the same points interpolated 0.977, a pass, and select,
    the campaign and the report each quoted one of the two."""
    moved = snapped["distance_deg"].to_numpy(float) > 1e-9
    if not moved.any():
        return None
    try:
        protocol = paper_protocol_for(meas) if points is None else as_protocol(
            pd.DataFrame(as_points(points), columns=["gamma_deg", "theta_deg"]))
        sampled, _ = sample_protocol(protocol, meas, tolerance_deg=SNAP_LIMIT_DEG,
                                     method="interpolate")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            other = fit(sampled, model, seed=seed)
    except (IrreflectError, FitError):
        return None
    r2 = float(metrics.r2(meas.power, other.predict(meas.gamma_deg, meas.theta_deg)))
    j = verdict.judgement
    status = judge(r2, j.reference_r2, n_points=verdict.n_points, n_params=verdict.n_params,
                   noise_fraction=verdict.extra.get("noise_fraction", 0.0)).status
    if status == j.status or (status != "fails" and j.status != "fails"):
        return None
    gaps = snapped["distance_deg"].to_numpy(float)[moved]
    return Cause(
        "placement-sensitive",
        f"the verdict rests on where {int(moved.sum())} of {what}'s {len(snapped)} points "
        f"are read: {meas.name} does not measure them, and taken at the nearest measured "
        f"points ({gaps.min():.2g}-{gaps.max():.2g} deg away) they give R^2 {j.r2:.4g} "
        f"against all points, interpolated along theta to their own angles (as "
        f"evaluate-protocol and the campaign's replay read them) R^2 {r2:.4g}, which "
        f"{status if status != 'pass' else 'passes'}: the {len(snapped)}-point fit is "
        "unstable on this material; a table measured at the protocol's angles settles it",
        remedy="")
