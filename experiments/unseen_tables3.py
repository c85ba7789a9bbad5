"""Held-out goniometer tables, third pass: grids, layouts and materials chosen by an outsider.

    python experiments/unseen_tables3.py OUTDIR --first SEED --count N

Writes N tables (kind i % len(KINDS), seed SEED + i) and OUTDIR/truth.json describing
what generated each one. The same seed gives byte-identical files. Written without
reading the project's own generators, so its assumptions are not theirs: receiver grids
dense near the mirror or different per angle of incidence, a mirror region blocked by the
source arm, only positive or few angles of incidence, a dynamic range of 1e5, powers of
1e-12 W, a BRDF-like normalisation, brushed metal, retroreflective paint, velvet, a
dielectric with a Fresnel rise, two-layer lacquer, odd sigma columns, several materials in
one file, Parquet, and CSV layouts (extra columns, column order, CRLF, BOM, comments,
semicolons).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

PAPER_GAMMAS = [-10.0, -20.0, -30.0, -40.0, -50.0, -60.0]


def _uniform(step: float, lo: float = -80.0, hi: float = 80.0) -> np.ndarray:
    return np.arange(lo, hi + 1e-9, step)


def _dense_near_mirror(gamma: float, fine: float, half: float, coarse: float) -> np.ndarray:
    mirror = -gamma
    near = np.arange(mirror - half, mirror + half + 1e-9, fine)
    far = np.arange(-80.0, 80.0 + 1e-9, coarse)
    far = far[np.abs(far - mirror) > half]
    grid = np.unique(np.round(np.concatenate([near, far]), 3))
    return grid[np.abs(grid) < 89.0]


def _fresnel_unpolarised(cos_i: np.ndarray, n: float) -> np.ndarray:
    sin_t2 = (1.0 - cos_i**2) / n**2
    cos_t = np.sqrt(np.clip(1.0 - sin_t2, 0.0, 1.0))
    rs = ((cos_i - n * cos_t) / (cos_i + n * cos_t)) ** 2
    rp = ((n * cos_i - cos_t) / (n * cos_i + cos_t)) ** 2
    return 0.5 * (rs + rp)


def _material(kind: str, g: np.ndarray, t: np.ndarray, p: dict) -> np.ndarray:
    """Radiant power at the receiver for incidence g and receiver angle t (deg)."""
    gr, tr = np.radians(g), np.radians(t)
    cos_g, cos_t = np.cos(gr), np.clip(np.cos(tr), 0.0, None)
    phi = -g - t  # angle from the mirror direction
    diffuse = p["kd"] * cos_g * cos_t
    if kind == "gauss":
        lobe = p["ks"] * np.exp(-0.5 * (phi / p["width"]) ** 2) * cos_g
    elif kind == "retro":
        back = g - t  # angle from the source direction (theta = gamma)
        lobe = p["kr"] * np.exp(-0.5 * (back / p["width"]) ** 2) * cos_g
        lobe += p["ks"] * np.exp(-0.5 * (phi / 4.0) ** 2) * cos_g
    elif kind == "velvet":
        sin_t = np.abs(np.sin(tr))
        lobe = p["kv"] * cos_g * sin_t ** p["exp"] * cos_t**0.2
        lobe += p["ks"] * np.exp(-0.5 * (phi / 20.0) ** 2) * cos_g
    elif kind == "fresnel":
        f = _fresnel_unpolarised(cos_g, p["n"])
        lobe = p["ks"] * f * np.exp(-0.5 * (phi / p["width"]) ** 2)
    elif kind == "lacquer":
        f = _fresnel_unpolarised(cos_g, 1.5)
        lobe = p["ks1"] * f * np.exp(-0.5 * (phi / p["w1"]) ** 2)
        lobe += p["ks2"] * cos_g * np.exp(-0.5 * (phi / p["w2"]) ** 2)
    else:
        raise ValueError(kind)
    return diffuse + lobe


def _grid(gammas, grid_fn) -> tuple[np.ndarray, np.ndarray]:
    gs, ts = [], []
    for gamma in gammas:
        th = grid_fn(gamma)
        gs.append(np.full(th.size, gamma))
        ts.append(th)
    return np.concatenate(gs), np.concatenate(ts)


def _noisy(rng, power: np.ndarray, rel: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    sigma = np.sqrt((rel * power) ** 2 + floor**2)
    return power + rng.normal(0.0, 1.0, power.size) * sigma, sigma


def _base(rng, name, kind, params, gammas, grid_fn, rel=0.02, floor_frac=0.005, scale=1.0):
    g, t = _grid(gammas, grid_fn)
    clean = _material(kind, g, t, params) * scale
    floor = floor_frac * float(np.max(clean))
    power, sigma = _noisy(rng, clean, rel, floor)
    df = pd.DataFrame({"gamma_deg": g, "theta_deg": np.round(t, 3), "power": power})
    truth = {"material": kind, "params": params, "gammas": list(map(float, gammas)),
             "noise": {"relative": rel, "floor": floor}, "scale": scale,
             "n_rows": int(len(df))}
    return df, sigma, truth


def _r(rng, lo, hi):
    return float(np.round(rng.uniform(lo, hi), 4))


def _brushed(rng, name):
    p = {"kd": _r(rng, 0.05, 0.15), "ks": _r(rng, 0.6, 1.2), "width": _r(rng, 12, 20)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS,
                      lambda g: _dense_near_mirror(g, 1.0, 10.0, 10.0))
    tr["notes"] = "brushed metal, broad specular; receivers 1 deg within 10 deg of the mirror, 10 deg elsewhere"
    return df, tr


def _per_gamma_grid(rng, name):
    p = {"kd": _r(rng, 0.3, 0.6), "ks": _r(rng, 0.5, 1.5), "width": _r(rng, 5, 9)}
    steps = {-15.0: 3.0, -35.0: 7.0, -55.0: 13.0, -70.0: 5.0}
    df, _, tr = _base(rng, name, "gauss", p, list(steps),
                      lambda g: _uniform(steps[g], -85 + (g % 3), 85))
    tr["notes"] = f"receiver step differs per gamma: {steps}"
    return df, tr


def _blocked(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 3, 6)}
    block = _r(rng, 5, 15)
    gammas = [-4.0, -8.0, -25.0, -45.0, -65.0]

    def grid(gamma):
        th = _uniform(2.0)
        return th[np.abs(th - gamma) > block]  # receiver blocked near the source

    df, _, tr = _base(rng, name, "gauss", p, gammas, grid)
    tr["notes"] = f"receiver blocked within {block} deg of the source; mirror of -4/-8 inside it"
    return df, tr


def _positive_mirrored(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(5.0))
    df["gamma_deg"] = -df["gamma_deg"]
    df["theta_deg"] = -df["theta_deg"]
    tr["notes"] = "paper frame mirrored: gamma > 0, mirror still at theta = -gamma"
    return df, tr


def _positive_magnitudes(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(5.0))
    df["gamma_deg"] = -df["gamma_deg"]
    tr["notes"] = "gamma written as magnitude (> 0), theta in the paper's sign: mirror at theta = +gamma"
    return df, tr


def _one_gamma(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, [-30.0], lambda g: _uniform(2.0))
    tr["notes"] = "a single angle of incidence"
    return df, tr


def _two_gammas(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, [-20.0, -50.0], lambda g: _uniform(4.0))
    tr["notes"] = "two angles of incidence"
    return df, tr


def _dynamic_range(rng, name):
    p = {"kd": 1e-5, "ks": 1.0, "width": _r(rng, 1.0, 2.0)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS,
                      lambda g: _dense_near_mirror(g, 0.5, 5.0, 5.0), floor_frac=1e-7)
    tr["notes"] = "lobe 1e5 times the diffuse level, resolved with 0.5 deg receivers"
    return df, tr


def _tiny(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, sigma, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(5.0),
                          scale=1e-12)
    df["sigma"] = sigma
    tr["notes"] = "powers of about 1e-12 W, with sigma"
    return df, tr


def _brdf_like(rng, name):
    p = {"kd": _r(rng, 0.3, 0.6), "ks": _r(rng, 0.5, 1.5), "width": _r(rng, 6, 10)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(5.0, -75, 75))
    cos_t = np.cos(np.radians(df["theta_deg"]))
    cos_g = np.cos(np.radians(df["gamma_deg"]))
    df["power"] = df["power"] / (cos_t * cos_g * np.pi)
    tr["notes"] = "BRDF-like: power / (pi cos gamma cos theta) [1/sr]; diffuse is flat in theta"
    return df, tr


def _retro(rng, name):
    p = {"kd": _r(rng, 0.1, 0.3), "kr": _r(rng, 1.0, 2.0), "width": _r(rng, 3, 6),
         "ks": _r(rng, 0.05, 0.2)}
    df, _, tr = _base(rng, name, "retro", p, PAPER_GAMMAS, lambda g: _uniform(3.0))
    tr["notes"] = "retroreflective paint: main lobe back toward the source (theta = gamma)"
    return df, tr


def _velvet(rng, name):
    p = {"kd": _r(rng, 0.1, 0.2), "kv": _r(rng, 0.4, 0.8), "exp": _r(rng, 3, 6),
         "ks": _r(rng, 0.02, 0.05)}
    df, _, tr = _base(rng, name, "velvet", p, PAPER_GAMMAS, lambda g: _uniform(4.0, -84, 84))
    tr["notes"] = "velvet/cloth: power rises toward grazing receivers"
    return df, tr


def _fresnel(rng, name):
    p = {"kd": _r(rng, 0.05, 0.1), "ks": _r(rng, 20, 40), "width": _r(rng, 2, 4),
         "n": _r(rng, 1.4, 1.7)}
    gammas = [-10.0, -30.0, -50.0, -65.0, -75.0, -82.0]
    df, _, tr = _base(rng, name, "fresnel", p, gammas,
                      lambda g: _dense_near_mirror(g, 1.0, 8.0, 6.0))
    tr["notes"] = "dielectric: specular follows Fresnel, a sharp rise at grazing incidence"
    return df, tr


def _lacquer(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks1": _r(rng, 30, 60), "w1": _r(rng, 1.0, 2.0),
         "ks2": _r(rng, 0.3, 0.8), "w2": _r(rng, 10, 16)}
    df, _, tr = _base(rng, name, "lacquer", p, PAPER_GAMMAS,
                      lambda g: _dense_near_mirror(g, 1.0, 6.0, 4.0))
    tr["notes"] = "two-layer lacquer: a sharp coat lobe and a broad base lobe"
    return df, tr


def _sigma_variant(mode):
    def make(rng, name):
        p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
        df, sigma, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(5.0))
        if mode == "zeros":
            sigma = sigma.copy()
            sigma[rng.choice(sigma.size, 5, replace=False)] = 0.0
        elif mode == "constant":
            sigma = np.full(sigma.size, float(np.round(np.median(sigma), 6)))
        elif mode == "relative":
            sigma = 0.02 * np.abs(df["power"].to_numpy())  # the floor left out
        elif mode == "allzero":
            sigma = np.zeros(sigma.size)
        df["sigma"] = sigma
        tr["notes"] = f"sigma column: {mode}"
        return df, tr
    return make


def _multi_material(rng, name):
    frames, truths = [], {}
    for mat, kind in (("paint", "gauss"), ("tile", "gauss"), ("carpet", "velvet")):
        if kind == "gauss":
            p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 0.5, 3.0), "width": _r(rng, 3, 10)}
        else:
            p = {"kd": 0.15, "kv": 0.5, "exp": 4.0, "ks": 0.03}
        df, _, tr = _base(rng, name, kind, p, PAPER_GAMMAS, lambda g: _uniform(5.0))
        df["material"] = mat
        frames.append(df)
        truths[mat] = tr
    return pd.concat(frames, ignore_index=True), {"materials": truths,
                                                  "notes": "three materials in one file"}


def _gauss_plain(rng, name, step=5.0):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    return _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(step))


def _layout(mode):
    def make(rng, name):
        df, sigma, tr = _gauss_plain(rng, name)
        tr["notes"] = f"layout: {mode}"
        tr["layout"] = mode
        if mode == "extra_columns":
            df["sigma"] = sigma
            df["temperature_c"] = np.round(21 + rng.normal(0, 0.3, len(df)), 2)
            df["operator"] = "ab"
            df = df[["power", "operator", "theta_deg", "sigma", "temperature_c", "gamma_deg"]]
        return df, tr
    return make


def _one_side(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, PAPER_GAMMAS, lambda g: _uniform(3.0, 0, 85))
    tr["notes"] = "receiver only on the mirror side (theta >= 0)"
    return df, tr


def _normal_only(rng, name):
    p = {"kd": _r(rng, 0.2, 0.4), "ks": _r(rng, 1.0, 3.0), "width": _r(rng, 4, 7)}
    df, _, tr = _base(rng, name, "gauss", p, [0.0, -5.0],
                      lambda g: _uniform(2.0)[np.abs(_uniform(2.0) - g) > 6])
    tr["notes"] = "normal and near-normal incidence only, receiver blocked within 6 deg of the source"
    return df, tr


def _decibel(rng, name):
    df, _, tr = _gauss_plain(rng, name)
    df["power"] = 10 * np.log10(np.clip(df["power"], 1e-6, None) / 1e-3)
    tr["notes"] = "power in dBm (negative numbers): a unit the tool does not take"
    return df, tr


# (kind, maker, file format)
KINDS = [
    ("brushed_metal", _brushed, "csv"),
    ("per_gamma_grid", _per_gamma_grid, "csv"),
    ("blocked_mirror", _blocked, "csv"),
    ("positive_mirrored", _positive_mirrored, "csv"),
    ("positive_magnitudes", _positive_magnitudes, "csv"),
    ("one_gamma", _one_gamma, "csv"),
    ("two_gammas", _two_gammas, "csv"),
    ("dynamic_range_1e5", _dynamic_range, "csv"),
    ("tiny_picowatt", _tiny, "csv"),
    ("brdf_normalised", _brdf_like, "csv"),
    ("retroreflective", _retro, "csv"),
    ("velvet", _velvet, "csv"),
    ("dielectric_fresnel", _fresnel, "csv"),
    ("lacquer_two_lobes", _lacquer, "csv"),
    ("sigma_zeros", _sigma_variant("zeros"), "csv"),
    ("sigma_constant", _sigma_variant("constant"), "csv"),
    ("sigma_relative", _sigma_variant("relative"), "csv"),
    ("sigma_all_zero", _sigma_variant("allzero"), "csv"),
    ("multi_material", _multi_material, "csv"),
    ("parquet_glossy", _lacquer, "parquet"),
    ("extra_columns", _layout("extra_columns"), "csv"),
    ("crlf", _layout("crlf"), "csv"),
    ("bom", _layout("bom"), "csv"),
    ("comments", _layout("comments"), "csv"),
    ("semicolon", _layout("semicolon"), "csv"),
    ("decimal_comma", _layout("decimal_comma"), "csv"),
    ("receiver_one_side", _one_side, "csv"),
    ("normal_incidence", _normal_only, "csv"),
    ("power_dbm", _decibel, "csv"),
    ("header_only", None, "csv"),
]


def _write(df: pd.DataFrame | None, path: Path, fmt: str, layout: str | None) -> None:
    if df is None:
        path.write_bytes(b"gamma_deg,theta_deg,power\n")
        return
    if fmt == "parquet":
        df.to_parquet(path, index=False, engine="pyarrow", compression="snappy")
        return
    sep, dec = ",", "."
    if layout == "semicolon":
        sep = ";"
    if layout == "decimal_comma":
        sep, dec = ";", ","
    text = df.to_csv(index=False, sep=sep, decimal=dec, float_format="%.10g", lineterminator="\n")
    if layout == "comments":
        text = "# goniometer run 7, detector PDA36A, gain 40 dB\n# units: W\n" + text
    if layout == "crlf":
        text = text.replace("\n", "\r\n")
    data = text.encode("utf-8")
    if layout == "bom":
        data = b"\xef\xbb\xbf" + data
    path.write_bytes(data)


def generate(outdir: Path, first: int, count: int) -> dict:
    outdir.mkdir(parents=True, exist_ok=True)
    truth = {}
    for i in range(count):
        seed = first + i
        kind, maker, fmt = KINDS[i % len(KINDS)]
        name = f"{i:02d}_{kind}_s{seed}"
        rng = np.random.default_rng(seed)
        df, tr = (None, {"notes": "header only"}) if maker is None else maker(rng, name)
        layout = tr.get("layout")
        path = outdir / f"{name}.{fmt}"
        _write(df, path, fmt, layout)
        truth[path.name] = {"kind": kind, "seed": seed, "format": fmt, **tr}
    (outdir / "truth.json").write_text(json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--count", type=int, default=len(KINDS))
    args = ap.parse_args()
    truth = generate(args.outdir, args.first, args.count)
    print(f"wrote {len(truth)} tables and truth.json to {args.outdir}")


if __name__ == "__main__":
    main()
