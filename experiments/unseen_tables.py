"""Dense goniometer tables from reflection models irreflect does not fit (held-out data).

A helper session wrote these at stop 39 to judge the adaptive campaign on data no rule
was tuned on: GGX and Beckmann microfacets with Smith or V-cavity shadowing and Schlick or
full Fresnel, Oren-Nayar and Lambert diffuse, a smooth dielectric whose specular share
rises to 1 at grazing, Ashikhmin-Shirley, a two-layer clear coat, velvet sheen,
Minnaert plus a Gaussian lobe, a retroreflective bump, a lobe peaking off the mirror; on
grids of 3-9 angles of incidence (normal incidence included, its mirror on the source),
receiver steps of 0.5-5 deg with and without a 0.25-deg ring round the mirror, receivers
over +-85 or -30..85 deg, 5 or 8 deg clear of the source; 0.5-3 % noise, an additive
floor, a gain drift per angle of incidence, one table with a sigma column; peaks from 1e-3
to 1e4. Seeded: the same tables every time. Usage::

    .venv/bin/python experiments/unseen_tables.py [--out out/unseen]
    .venv/bin/python experiments/unseen_tables.py --random 30 --out out/unseen2
    .venv/bin/python experiments/unseen_tables.py --random 30 --first-seed 9100 --out out/unseen3
    .venv/bin/python experiments/unseen_tables.py --cornell 20 --first-seed 7000 --out out/cornell
    .venv/bin/python experiments/bench_campaign.py --real-only --data-dir out/unseen \
        --generations 30 --workers 2

Convention (irreflect's): gamma <= 0 (source side), theta signed, mirror at theta = -gamma,
phi = -gamma - theta; power = P0 * f_r(gamma, theta) * cos(theta) [* cos|gamma| if irr].
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

D2R = np.pi / 180


# ----------------------------------------------------------------------------- physics
def fresnel_dielectric(cosb, n):
    """Full unpolarised Fresnel reflectance, air -> dielectric of index n."""
    cosb = np.clip(cosb, 0, 1)
    sin2t = (1 - cosb**2) / n**2
    cost = np.sqrt(np.clip(1 - sin2t, 0, 1))
    rs = (cosb - n * cost) / (cosb + n * cost)
    rp = (n * cosb - cost) / (n * cosb + cost)
    return 0.5 * (rs**2 + rp**2)


def schlick(cosb, f0):
    return f0 + (1 - f0) * (1 - np.clip(cosb, 0, 1)) ** 5


def geometry(gamma, theta):
    gi = np.abs(gamma) * D2R           # incidence angle (rad)
    tr = theta * D2R
    th_h = (tr - gi) / 2               # half-vector tilt from the normal
    beta = np.abs(tr + gi) / 2         # angle between L and H
    return gi, tr, th_h, beta


def d_ggx(th_h, a):
    c = np.cos(th_h)
    t2 = np.tan(th_h) ** 2
    return a**2 / (np.pi * c**4 * (a**2 + t2) ** 2)


def d_beckmann(th_h, m):
    c = np.cos(th_h)
    return np.exp(-np.tan(th_h) ** 2 / m**2) / (np.pi * m**2 * c**4)


def g1_smith_ggx(t, a):
    return 2 / (1 + np.sqrt(1 + a**2 * np.tan(np.abs(t)) ** 2))


def g_vcavity(gi, tr, th_h):
    ch = np.cos(th_h)
    ci, co = np.cos(gi), np.cos(np.abs(tr))
    cb = np.cos((tr + gi) / 2)
    return np.minimum(1, np.minimum(2 * ch * co / cb, 2 * ch * ci / cb))


def oren_nayar(gi, tr, sigma):
    s2 = sigma**2
    A = 1 - 0.5 * s2 / (s2 + 0.33)
    B = 0.45 * s2 / (s2 + 0.09)
    ti, to = gi, np.abs(tr)
    # in-plane: receiver on the source side (theta<0) -> dphi = 0 -> cos = 1; far side -> -1
    cosdphi = np.where(tr < 0, 1.0, -1.0)
    al, be = np.maximum(ti, to), np.minimum(ti, to)
    return (A + B * np.maximum(0, cosdphi) * np.sin(al) * np.tan(be)) / np.pi


def make_model(kind, p):
    """Return f(gamma_deg, theta_deg) -> BRDF*cos(theta) (unnormalised)."""

    def f(gamma, theta):
        gamma = np.asarray(gamma, float)
        theta = np.asarray(theta, float)
        gi, tr, th_h, beta = geometry(gamma, theta)
        cos_o = np.cos(tr)
        cos_i = np.cos(gi)
        out = np.zeros(np.broadcast(gamma, theta).shape)
        if kind == "ggx":  # GGX + Smith + Schlick + Lambert
            spec = d_ggx(th_h, p["a"]) * schlick(np.cos(beta), p["f0"]) * \
                g1_smith_ggx(gi, p["a"]) * g1_smith_ggx(tr, p["a"]) / (4 * cos_i * cos_o)
            out = p["kd"] / np.pi + p["ks"] * spec
        elif kind == "beckmann_on":  # Beckmann + full Fresnel + V-cavity + Oren-Nayar
            F = fresnel_dielectric(np.cos(beta), p["n"])
            spec = d_beckmann(th_h, p["m"]) * F * g_vcavity(gi, tr, th_h) / (4 * cos_i * cos_o)
            out = p["kd"] * oren_nayar(gi, tr, p["sigma"]) + p["ks"] * spec
        elif kind == "fresnel_sat":  # smooth dielectric: diffuse * (1-F_i)(1-F_o), spec * F
            F = fresnel_dielectric(np.cos(beta), p["n"])
            spec = d_ggx(th_h, p["a"]) * F * g1_smith_ggx(gi, p["a"]) * \
                g1_smith_ggx(tr, p["a"]) / (4 * cos_i * cos_o)
            Fi = fresnel_dielectric(cos_i, p["n"])
            Fo = fresnel_dielectric(cos_o, p["n"])
            out = p["kd"] / np.pi * (1 - Fi) * (1 - Fo) + spec
        elif kind == "retro":  # Lambert + Gaussian lobe in phi + retro bump at theta = gamma
            phi = -gamma - theta
            out = (p["kd"] / np.pi + p["ks"] * np.exp(-(phi / p["w"]) ** 2) / cos_o
                   + p["kr"] * np.exp(-((theta - gamma) / p["wr"]) ** 2) / cos_o)
        elif kind == "offspec":  # lobe peaking off the mirror, toward grazing
            shift = p["k"] * np.abs(gamma) + p["s0"]
            phi = -gamma - theta + shift      # peak at theta = |gamma| + shift
            out = p["kd"] / np.pi + p["ks"] * np.cos(np.clip(phi * D2R, -np.pi / 2, np.pi / 2)) ** p["n"] / cos_o
        elif kind == "ashikhmin":  # Ashikhmin-Shirley isotropic + its coupled diffuse
            nexp = p["n"]
            spec = (nexp + 1) / (8 * np.pi) * np.cos(th_h) ** nexp / (
                np.cos(beta) * np.maximum(cos_i, cos_o)) * schlick(np.cos(beta), p["rs"])
            diff = 28 * p["rd"] / (23 * np.pi) * (1 - p["rs"]) * (1 - (1 - cos_i / 2) ** 5) * \
                (1 - (1 - cos_o / 2) ** 5)
            out = diff + spec
        elif kind == "clearcoat":  # sharp GGX clear coat + broad GGX base + Lambert
            Fc = fresnel_dielectric(np.cos(beta), 1.5)
            c = d_ggx(th_h, p["ac"]) * Fc * g1_smith_ggx(gi, p["ac"]) * \
                g1_smith_ggx(tr, p["ac"]) / (4 * cos_i * cos_o)
            b = d_ggx(th_h, p["ab"]) * schlick(np.cos(beta), p["f0"]) * g1_smith_ggx(gi, p["ab"]) * \
                g1_smith_ggx(tr, p["ab"]) / (4 * cos_i * cos_o)
            out = p["kd"] / np.pi + p["kc"] * c + p["kb"] * b
        elif kind == "sheen":  # velvet/fabric: sheen rising at grazing + Oren-Nayar
            sh = np.sin(np.abs(tr)) ** p["e"] * np.sin(gi) ** p["e"] / (cos_o + 0.05)
            out = p["kd"] * oren_nayar(gi, tr, p["sigma"]) + p["ksh"] * sh
        elif kind == "minnaert_gauss":  # Minnaert limb-darkened diffuse + Gaussian in half-angle
            diff = (cos_i * cos_o) ** (p["k"] - 1) / np.pi
            spec = np.exp(-(th_h / (p["s"] * D2R)) ** 2) / (cos_o * cos_i)
            out = p["kd"] * diff + p["ks"] * spec
        elif kind == "lambert":  # matte: Oren-Nayar only
            out = oren_nayar(gi, tr, p["sigma"])
        else:
            raise ValueError(kind)
        pw = out * cos_o
        if p.get("irr"):
            pw = pw * cos_i
        return pw

    return f


# ----------------------------------------------------------------------------- grids
def grid(gammas, tmin, tmax, step, ring=False, hole=5.0):
    G, T = [], []
    for g in gammas:
        th = np.round(np.arange(tmin, tmax + 1e-9, step), 4)
        if ring:
            m = -g
            th = np.union1d(th, np.round(np.arange(m - 3, m + 3 + 1e-9, 0.25), 4))
            th = th[(th >= tmin) & (th <= tmax)]
        th = th[np.abs(th - g) > hole]            # the receiver cannot sit on the source
        G += [g] * len(th)
        T += list(th)
    return np.array(G, float), np.array(T, float)


# ----------------------------------------------------------------------------- the tables
G10 = [-0, -10, -20, -30, -40, -50, -60, -70, -80]
G5U = [-8, -23, -41, -57, -72]
G3 = [-15, -45, -75]
G7 = [-10, -20, -30, -40, -50, -60, -70]

SPECS = [
    # label, kind, params, gammas, (tmin, tmax, step, ring, hole), noise dict
    ("ggx-lambert-a0.1", "ggx", dict(a=0.1, f0=0.04, ks=1.0, kd=0.6), G10, (-85, 85, 2, True, 5), dict(rel=0.01)),
    ("ggx-glossy-a0.03", "ggx", dict(a=0.03, f0=0.05, ks=1.0, kd=0.3), G7, (-85, 85, 1, True, 5), dict(rel=0.02, add=1e-4)),
    ("ggx-rough-a0.4-uneven5", "ggx", dict(a=0.4, f0=0.04, ks=1.0, kd=0.5), G5U, (-85, 85, 1, False, 5), dict(rel=0.005)),
    ("ggx-3gammas-step0.5", "ggx", dict(a=0.15, f0=0.06, ks=1.0, kd=0.8, irr=1), G3, (-85, 85, 0.5, False, 5), dict(rel=0.01, drift=0.02)),
    ("beckmann-ON-m0.2", "beckmann_on", dict(m=0.2, n=1.5, ks=1.0, kd=0.7, sigma=0.3), G10, (-85, 85, 2, False, 5), dict(rel=0.01)),
    ("beckmann-ON-m0.08-ring", "beckmann_on", dict(m=0.08, n=1.6, ks=1.0, kd=0.4, sigma=0.5), G7, (-85, 85, 2, True, 5), dict(rel=0.015, add=3e-4)),
    ("beckmann-ON-half-range", "beckmann_on", dict(m=0.15, n=1.5, ks=1.0, kd=0.6, sigma=0.4), G7, (-30, 85, 1, False, 5), dict(rel=0.01)),
    ("fresnel-sat-n1.5-0to80", "fresnel_sat", dict(a=0.05, n=1.5, kd=0.5), G10, (-85, 85, 1, True, 5), dict(rel=0.01, add=1e-4)),
    ("fresnel-sat-n1.4-rough", "fresnel_sat", dict(a=0.2, n=1.4, kd=0.8), G10, (-85, 85, 2, False, 5), dict(rel=0.02)),
    ("fresnel-sat-3g-half", "fresnel_sat", dict(a=0.08, n=1.5, kd=0.3, irr=1), G3, (-30, 85, 0.5, True, 5), dict(rel=0.01, drift=0.02)),
    ("retro-bump-lambert", "retro", dict(kd=1.0, ks=0.3, w=8, kr=0.25, wr=10), G7, (-85, 85, 1, False, 5), dict(rel=0.01)),
    ("retro-strong-uneven", "retro", dict(kd=0.5, ks=0.5, w=5, kr=0.5, wr=12), G5U, (-85, 85, 2, False, 5), dict(rel=0.02, add=1e-3)),
    ("offspec-k0.3", "offspec", dict(kd=0.8, ks=0.5, n=200, k=0.3, s0=0), G7, (-85, 85, 1, False, 5), dict(rel=0.01)),
    ("offspec-s5-ring", "offspec", dict(kd=0.5, ks=1.0, n=800, k=0.1, s0=3), G10[1:], (-85, 85, 2, True, 5), dict(rel=0.01)),
    ("ashikhmin-n100", "ashikhmin", dict(n=100, rs=0.05, rd=0.7), G10, (-85, 85, 2, False, 5), dict(rel=0.01)),
    ("ashikhmin-n2000-step0.5", "ashikhmin", dict(n=2000, rs=0.04, rd=0.5), G3, (-85, 85, 0.5, False, 5), dict(rel=0.03, add=1e-3)),
    ("clearcoat-2lobes", "clearcoat", dict(ac=0.02, ab=0.25, f0=0.3, kc=1.0, kb=1.0, kd=0.3), G7, (-85, 85, 1, True, 5), dict(rel=0.01)),
    ("clearcoat-uneven-half", "clearcoat", dict(ac=0.04, ab=0.3, f0=0.2, kc=1.0, kb=0.8, kd=0.5), G5U, (-30, 85, 1, True, 5), dict(rel=0.02, drift=0.03)),
    ("sheen-velvet", "sheen", dict(kd=0.6, sigma=0.6, ksh=0.3, e=3), G10, (-85, 85, 2, False, 5), dict(rel=0.01)),
    ("minnaert-gauss", "minnaert_gauss", dict(kd=0.8, k=0.7, ks=0.3, s=4), G7, (-85, 85, 1, False, 5), dict(rel=0.01)),
    ("matte-ON-sigma0.8", "lambert", dict(sigma=0.8), G10, (-85, 85, 5, False, 5), dict(rel=0.005, add=2e-4)),
    ("matte-ON-0to80-step1", "lambert", dict(sigma=0.3, irr=1), G10, (-85, 85, 1, False, 5), dict(rel=0.02, drift=0.03)),
    ("ggx-mirrorlike-a0.01", "ggx", dict(a=0.01, f0=0.9, ks=1.0, kd=0.02), G7, (-85, 85, 1, True, 5), dict(rel=0.01, add=1e-5)),
    ("beckmann-ON-3g-step5-hole8", "beckmann_on", dict(m=0.3, n=1.5, ks=1.0, kd=0.5, sigma=0.3), G3, (-85, 85, 3, True, 8), dict(rel=0.01)),
    ("ggx-sigma-col", "ggx", dict(a=0.07, f0=0.05, ks=1.0, kd=0.5), G10, (-85, 85, 1, False, 5), dict(rel=0.01, add=1e-4, sigma=1)),
]
# peak power from 1e-3 to 1e4, log-spaced over the tables in a shuffled order
_PEAKS = 10 ** np.linspace(-3, 4, len(SPECS))
np.random.default_rng(7).shuffle(_PEAKS)


def truth(label):
    i = [s[0] for s in SPECS].index(label)
    lab, kind, p, gammas, (tmin, tmax, step, ring, hole), noise = SPECS[i]
    f = make_model(kind, p)
    G, T = grid(gammas, tmin, tmax, step, ring, hole)
    scale = _PEAKS[i] / np.max(f(G, T))
    return lambda g, t: scale * f(np.asarray(g, float), np.asarray(t, float))


def measure(label, gamma, theta, rng):
    """One noisy reading of the instrument (for hand-driven campaigns)."""
    i = [s[0] for s in SPECS].index(label)
    noise = SPECS[i][5]
    y = truth(label)(gamma, theta)
    y = y * (1 + noise.get("rel", 0) * rng.standard_normal(np.shape(y)))
    y = y + noise.get("add", 0) * _PEAKS[i] * rng.standard_normal(np.shape(y))
    return y


_KINDS = ("ggx", "beckmann_on", "fresnel_sat", "ashikhmin", "clearcoat", "minnaert_gauss",
          "lambert", "sheen", "retro", "offspec")
_GRIDS = (G10, G5U, G3, G7, [-5, -25, -45, -65, -80], [0, -20, -40, -60, -80])


def _random_params(kind, rng):
    """One draw of a model's parameters (a second held-out set, stop 39)."""
    u = rng.uniform
    draws = {
        "ggx": lambda: dict(a=u(0.02, 0.4), f0=u(0.03, 0.3), ks=1.0, kd=u(0.05, 1)),
        "beckmann_on": lambda: dict(m=u(0.05, 0.4), n=u(1.3, 1.8), ks=1.0, kd=u(0.1, 1),
                                    sigma=u(0, 0.8)),
        "fresnel_sat": lambda: dict(a=u(0.03, 0.3), n=u(1.3, 1.8), kd=u(0.1, 1)),
        "ashikhmin": lambda: dict(n=10 ** u(1.5, 3.5), rs=u(0.03, 0.2), rd=u(0.2, 0.9)),
        "clearcoat": lambda: dict(ac=u(0.01, 0.06), ab=u(0.15, 0.4), f0=u(0.1, 0.4), kc=1.0,
                                  kb=u(0.3, 1), kd=u(0.1, 0.6)),
        "minnaert_gauss": lambda: dict(kd=u(0.3, 1), k=u(0.5, 1.0), ks=u(0.1, 0.6), s=u(2, 10)),
        "lambert": lambda: dict(sigma=u(0.1, 0.9)),
        "sheen": lambda: dict(kd=u(0.3, 1), sigma=u(0.2, 0.8), ksh=u(0.1, 0.5), e=u(2, 5)),
        "retro": lambda: dict(kd=u(0.3, 1), ks=u(0.1, 0.6), w=u(3, 10), kr=u(0.05, 0.5),
                              wr=u(5, 15)),
        "offspec": lambda: dict(kd=u(0.3, 1), ks=u(0.3, 1), n=10 ** u(1.5, 3), k=u(0.05, 0.3),
                                s0=u(0, 4)),
    }
    p = {k: float(v) for k, v in draws[kind]().items()}
    if rng.random() < 0.3:
        p["irr"] = 1
    return p


def _write_table(path: Path, G, T, y, sigma=None) -> None:
    """One table as CSV (``gamma_deg, theta_deg, power`` and, given, ``sigma``)."""
    with open(path, "w") as fh:
        fh.write("gamma_deg,theta_deg,power" + (",sigma" if sigma is not None else "") + "\n")
        for k in range(len(G)):
            fh.write(f"{G[k]:g},{T[k]:g},{y[k]:.6g}"
                     + (f",{sigma[k]:.4g}" if sigma is not None else "") + "\n")


def write_random(out: Path, count: int, first_seed: int) -> None:
    """``count`` tables of random draws of the models, grids and noise above, seeded
    ``first_seed + i`` (``--random``: the second held-out set of stop 39)."""
    for i in range(count):
        rng = np.random.default_rng(first_seed + i)
        kind = _KINDS[i % len(_KINDS)]
        p = _random_params(kind, rng)
        gammas = _GRIDS[int(rng.integers(len(_GRIDS)))]
        tmin = float(rng.choice([-85, -85, -30]))
        step = float(rng.choice([0.5, 1, 2, 3]))
        ring = bool(rng.random() < 0.4)
        hole = float(rng.choice([3, 5, 8]))
        G, T = grid(gammas, tmin, 85, step, ring, hole)
        y0 = make_model(kind, p)(G, T)
        y0 = y0 / np.max(y0) * float(10 ** rng.uniform(-3, 4))
        rel = float(rng.uniform(0.005, 0.03))
        add = float(rng.choice([0, 1e-4, 1e-3])) * y0.max()
        y = y0 * (1 + rel * rng.standard_normal(y0.shape)) + add * rng.standard_normal(y0.shape)
        _write_table(out / f"{kind}-{i}.csv", G, T, y)


_CORNELL_KINDS = ("ggx", "beckmann_on", "fresnel_sat", "ashikhmin", "clearcoat",
                  "minnaert_gauss", "lambert", "ggx", "beckmann_on", "clearcoat")


def write_cornell(out: Path, count: int, first_seed: int, grid_table: Path) -> None:
    """``count`` tables on the grid of a real Cornell set (its 108 settings: 7 angles of
    incidence, receivers about 8 deg apart, a gap round the source), random draws of the
    models above, peaks of 1e-4 to 1 and 0.5-2 % relative noise, seeded ``first_seed +
    i`` (``--cornell``: the held-out set of stop 47, 20 tables from seed 7000)."""
    from irreflect.data import read_measurements

    table = read_measurements(grid_table)  # a table irreflect refuses is refused in one line
    G, T = table.gamma_deg, table.theta_deg
    for i in range(count):
        rng = np.random.default_rng(first_seed + i)
        kind = _CORNELL_KINDS[i % len(_CORNELL_KINDS)]
        p = _random_params(kind, rng)
        y0 = make_model(kind, p)(G, T)
        y0 = y0 / np.max(y0) * float(10 ** rng.uniform(-4, 0))
        y = y0 * (1 + float(rng.uniform(0.005, 0.02)) * rng.standard_normal(y0.shape))
        _write_table(out / f"cornell-{kind}-{first_seed + i}.csv", G, T, y)


def main(argv=None):
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="out/unseen", help="folder of the tables")
    parser.add_argument("--random", type=int, default=0, metavar="N",
                        help="write N tables of random draws instead (seeds FIRST + i)")
    parser.add_argument("--first-seed", type=int, default=9000, metavar="FIRST",
                        help="the first seed of --random (default 9000: the set of stop 39; "
                             "9100: the third held-out set, drawn at stop 40)")
    parser.add_argument("--cornell", type=int, default=0, metavar="N",
                        help="write N tables on the grid of --grid-table instead (seeds "
                             "FIRST + i; 20 from 7000: the Cornell-grid set of stop 47)")
    parser.add_argument("--grid-table", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "datasets"
                        / "real" / "cornell" / "cornell_cayman.csv",
                        help="the table whose settings --cornell uses (default the real "
                             "Cornell Cayman set)")
    args = parser.parse_args(argv)
    if args.cornell < 0:
        parser.error(f"--cornell N: expected a count of 0 or more, found {args.cornell}")
    if args.cornell and not args.grid_table.is_file():
        parser.error(f"--grid-table: expected a CSV table, found no file at {args.grid_table}")
    if args.random < 0:
        parser.error(f"--random N: expected a count of 0 or more, found {args.random}")
    if args.first_seed < 0:
        parser.error(f"--first-seed: expected a seed of 0 or more, found {args.first_seed}")
    from irreflect._atomic import atomic_directory
    from irreflect.errors import IrreflectError

    # written whole or not at all, into a folder no input is in (claim_output)
    try:
        with atomic_directory(Path(args.out), command="experiments/unseen_tables.py") as tmp:
            if args.cornell:
                write_cornell(tmp, args.cornell, args.first_seed, args.grid_table)
            elif args.random:
                write_random(tmp, args.random, args.first_seed)
            else:
                _write_fixed(tmp)
    except IrreflectError as exc:
        parser.error(str(exc))
    print(f"wrote {args.cornell or args.random or len(SPECS)} tables to {args.out}")


def _write_fixed(out: Path) -> None:
    """The 25 tables of :data:`SPECS` and their ``index.json``."""
    rows = []
    for i, (lab, kind, p, gammas, (tmin, tmax, step, ring, hole), noise) in enumerate(SPECS):
        rng = np.random.default_rng(1000 + i)
        G, T = grid(gammas, tmin, tmax, step, ring, hole)
        y0 = truth(lab)(G, T)
        assert np.all(np.isfinite(y0)), lab
        peak = _PEAKS[i]
        gain = np.ones_like(y0)
        if noise.get("drift"):
            for g in np.unique(G):
                gain[G == g] = 1 + noise["drift"] * rng.standard_normal()
        sig = np.sqrt((noise.get("rel", 0) * y0) ** 2 + (noise.get("add", 0) * peak) ** 2)
        y = y0 * gain * (1 + noise.get("rel", 0) * rng.standard_normal(y0.shape))
        y = y + noise.get("add", 0) * peak * rng.standard_normal(y0.shape)
        _write_table(out / f"{lab}.csv", G, T, y, sig if noise.get("sigma") else None)
        rows.append(dict(label=lab, kind=kind, points=len(G), peak=float(peak),
                         gammas=list(gammas), theta=[tmin, tmax, step], ring=ring, hole=hole,
                         noise=noise, params=p))
    (out / "index.json").write_text(json.dumps(rows, indent=1))
    for r in rows:
        print(f"{r['label']:28s} {r['points']:5d} peak {r['peak']:.3g}")


if __name__ == "__main__":
    main()
