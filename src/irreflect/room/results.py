"""Numbers derived from a room simulation, and the files ``irreflect room`` writes.

Per emitter-receiver pair: DC gain ``H(0)`` (received / emitted power) in total and per
order (0 = line of sight), mean delay and RMS delay spread of the whole response
(Barry's definitions, from exact delay moments), and for phase-based ranging at the
emitter's modulation frequency ``f``: the phase of ``H(f) = sum_i P_i exp(-j 2 pi f tau_i)``
relative to the geometric line-of-sight delay ``d / c``, and the equivalent range error
``-c dphi / (2 pi f)`` (positive: the multipath makes the range look longer).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import numpy as np

from .._atomic import atomic_directory
from .._jsonio import finite
from .kernels import C_LIGHT

if TYPE_CHECKING:
    import pandas as pd


def link_metrics(result, link) -> dict:
    """The scalar results of one emitter-receiver pair."""
    scene = result.scene
    em, rx = scene.emitters[link.emitter], scene.receivers[link.receiver]
    P = float(em.power_w)
    total = float(np.sum(link.power_w))
    out = {
        "emitter": em.name, "receiver": rx.name, "grid": rx.grid or "",
        "ix": rx.grid_index[0] if rx.grid_index else -1,
        "iy": rx.grid_index[1] if rx.grid_index else -1,
        "x_m": float(rx.position[0]), "y_m": float(rx.position[1]), "z_m": float(rx.position[2]),
        "distance_m": float(np.linalg.norm(rx.position - em.position)),
        "method": result.method,
        "received_power_w": total,
        "dc_gain_total": total / P,
        "dc_gain_los": float(link.power_w[0]) / P,
        "dc_gain_reflected": float(np.sum(link.power_w[1:])) / P,
    }
    for k in range(1, len(link.power_w)):
        out[f"dc_gain_b{k}"] = float(link.power_w[k]) / P
        if result.method == "montecarlo":
            out[f"dc_gain_b{k}_stderr"] = float(link.stderr_w[k]) / P
    if result.method == "montecarlo" and len(link.power_w) > 1:
        out["dc_gain_reflected_stderr"] = float(np.sqrt(np.sum(link.stderr_w[1:] ** 2))) / P
    M0, M1, M2 = total, float(np.sum(link.m1)), float(np.sum(link.m2))
    if M0 > 0:
        mean = M1 / M0
        rms = np.sqrt(max(M2 / M0 - mean * mean, 0.0))
        out["mean_delay_ns"] = mean * 1e9
        out["rms_delay_spread_ns"] = rms * 1e9
    else:
        out["mean_delay_ns"] = out["rms_delay_spread_ns"] = np.nan
    out["modulation_hz"] = float(em.modulation_hz)
    phase, rng = ranging_error(link.phasor.sum(), link.los_delay_s, em.modulation_hz)
    out["phase_error_deg"] = phase
    out["range_error_m"] = rng
    return out


def ranging_error(phasor_total: complex, los_delay_s: float, modulation_hz: float):
    """Phase error (deg) and range error (m) of phase-based ranging at ``modulation_hz``.

    ``phasor_total`` is ``sum_i P_i exp(-j 2 pi f tau_i)`` over all paths (W); the true range
    is ``c * los_delay_s``. NaN when there is no modulation or no received signal.
    """
    if modulation_hz <= 0 or abs(phasor_total) == 0:
        return np.nan, np.nan
    omega = 2 * np.pi * modulation_hz
    dphi = float(np.angle(phasor_total * np.exp(1j * omega * los_delay_s)))
    return float(np.degrees(dphi)), float(-C_LIGHT * dphi / omega)


def summary_table(result) -> pd.DataFrame:
    import pandas as pd  # deferred: a room run without tables need not load it

    rows = [link_metrics(result, result.links[key]) for key in sorted(result.links)]
    return pd.DataFrame(rows)


def bounces_table(result) -> pd.DataFrame:
    import pandas as pd  # deferred: a room run without tables need not load it

    rows = []
    est = result.error_estimate or {}
    for (e, r), link in sorted(result.links.items()):
        P = result.scene.emitters[e].power_w
        err = est.get((e, r))
        for k in range(len(link.power_w)):
            p = float(link.power_w[k])
            rows.append({
                "emitter": result.scene.emitters[e].name,
                "receiver": result.scene.receivers[r].name, "order": k,
                "dc_gain": p / P, "stderr": float(link.stderr_w[k]) / P,
                "mean_delay_ns": float(link.m1[k] / p * 1e9) if p > 0 else np.nan,
                "reflected_power_fraction": (float(link.reflected_w[k - 1]) / P
                                             if k >= 1 else np.nan),
                "estimated_error": (float(err[k]) if err is not None and k >= 1
                                    else np.nan),
            })
    return pd.DataFrame(rows)


def impulse_table(result, receivers=None) -> pd.DataFrame:
    """h(t) in long form, non-zero bins only: emitter, receiver, order, ``t_ns`` (the *start*
    of the bin: the bin holds the power arriving in [t_ns, t_ns + dt)), power_w (power in the
    bin)."""
    import pandas as pd  # deferred: a room run without tables need not load it

    parts = []
    for (e, r), link in sorted(result.links.items()):
        if receivers is not None and r not in receivers:
            continue
        t = np.arange(link.hist.shape[1]) * result.dt_s * 1e9
        k, b = np.nonzero(link.hist)
        parts.append(pd.DataFrame({
            "emitter": result.scene.emitters[e].name, "receiver": result.scene.receivers[r].name,
            "order": k, "t_ns": np.round(t[b], 6), "power_w": link.hist[k, b].astype(float)}))
    if not parts:
        return pd.DataFrame(columns=["emitter", "receiver", "order", "t_ns", "power_w"])
    return pd.concat(parts, ignore_index=True)


def grid_values(result, summary: pd.DataFrame, grid, column: str, emitter: str):
    """(x, y, values (ny, nx)) of a summary column over a receiver grid (NaN where no receiver)."""
    sub = summary[(summary.grid == grid.name) & (summary.emitter == emitter)]
    values = np.full((len(grid.y_m), len(grid.x_m)), np.nan)
    values[sub.iy.to_numpy(), sub.ix.to_numpy()] = sub[column].to_numpy()
    return grid.x_m, grid.y_m, values


def run_info(result) -> dict:
    scene = result.scene
    return {
        "scene": scene.name, "scene_file": scene.path, "method": result.method,
        "bounces": result.bounces, "cell_m": result.cell_m, "cells": result.n_cells,
        "rays_per_link": result.rays, "seed": result.seed,
        "time_resolution_ns": result.dt_s * 1e9, "seconds": round(result.seconds, 3),
        "ray_bounces_per_s": result.ray_bounces_per_s,
        "brdf": result.brdf,
        "materials": {k: {"source": m.source, "model": m.model, "reflectance": m.reflectance,
                          "scale": m.scale, "surface_model": m.brdf,
                          "albedo_range": [float(m.rho_table.min()), float(m.rho_table.max())],
                          "fidelity": m.fidelity, "warnings": list(m.warnings)}
                      for k, m in scene.materials.items()},
        "error_estimate": (None if result.error_estimate is None else
                           {f"{scene.emitters[e].name} -> {scene.receivers[r].name}": v.tolist()
                            for (e, r), v in result.error_estimate.items()}),
        "emitters": [e.name for e in scene.emitters],
        "receivers": len(scene.receivers), "notes": list(result.notes),
    }


#: what the files' columns mean (written into run.json and the Parquet files' metadata)
FILES = {
    "summary": "one row per emitter-receiver pair: DC gains (total, LoS, per reflection, "
               "Monte Carlo standard errors), mean delay and RMS delay spread (ns), phase error "
               "(deg) and range error (m) of phase-based ranging at the emitter's modulation",
    "bounces": "one row per pair and order (0 = line of sight): DC gain, standard error (Monte "
               "Carlo), mean delay (ns), power left after that many reflections per watt "
               "emitted, and the recursive method's estimated relative error of the order "
               "(from a run at twice the cell size, and with glossy materials that run with a "
               "quarter of the lobe rays; NaN for Monte Carlo)",
    "impulse_response": "h(t), non-zero bins only: t_ns is the START of each delay bin; the "
                        "bin holds the power (W) arriving in [t_ns, t_ns + dt) with dt = "
                        "time_resolution_ns of run.json",
}


def write_results(result, out_dir, figures=None) -> list[str]:
    """Write every number (CSV and Parquet) into ``out_dir``, atomically; with ``figures``
    (a figure writer such as :func:`irreflect.plots.room.write_figures`, called as
    ``figures(result, summary, singles, folder) -> file names``) the figures too, in the
    same atomic step. The writer is passed in because drawing is a higher layer."""
    written = []
    summary = summary_table(result)
    bounces = bounces_table(result)
    singles = [i for i, r in enumerate(result.scene.receivers) if r.grid is None]
    impulse = impulse_table(result)
    with atomic_directory(out_dir, "--out", command="room") as tmp:
        for name, df in (("summary", summary), ("bounces", bounces), ("impulse_response", impulse)):
            df.to_csv(tmp / f"{name}.csv", index=False)
            df.attrs["description"] = FILES[name]
            df.to_parquet(tmp / f"{name}.parquet", index=False)
            written += [f"{name}.csv", f"{name}.parquet"]
        info = run_info(result)
        info["files"] = FILES
        (tmp / "run.json").write_text(json.dumps(finite(info), indent=2, default=str,
                                                 allow_nan=False) + "\n")
        written.append("run.json")
        if figures is not None:
            written += figures(result, summary, singles, tmp)
    return written


def safe_name(text: str) -> str:
    """``text`` with every character but letters, digits, '-' and '_' replaced by '_'
    (for file names)."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in text)
