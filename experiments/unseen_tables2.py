#!/usr/bin/env python3
"""A second held-out generator of goniometer tables, written at stop 45 by a helper session
that did not read experiments/unseen_tables.py or irreflect.synthetic (so that it does not
share their assumptions).

Families (the family is chosen by the seed): Cook-Torrance (Beckmann, Schlick, V-cavity),
isotropic Ward, Blinn-Phong with dielectric Fresnel, He-Torrance-like (a coherent spike on
a wide lobe), Hapke / Lommel-Seeliger with an opposition surge, a layered coat whose share
saturates at 1, Lambert with a 1-8 % lobe, a mirror lobe 0.5-2 deg wide, irreflect's own
two-lobe law, Oren-Nayar with a small lobe. Artefacts: a box or Gaussian receiver aperture
of 1-4 deg, a clipped peak (a saturated detector), a dark offset, shot or Gaussian noise of
0.3-5 %, an 8-12 bit converter, 1-8 % gain drift per angle of incidence, 2-3 repeats of
every setting, shuffled rows; 2-10 irregular angles of incidence, receiver steps of 0.2-10
deg, asymmetric receiver ranges (some to +-90), holes, peaks from 2e-6 to 6e5; some tables
with a sigma or a material column. Seeded: the same seed gives the same table.

Conventions: gamma_deg <= 0 (source side), theta_deg signed, mirror at theta = -gamma,
degrees. Usage (docs/campaign.md, "At stop 45")::

    .venv/bin/python experiments/unseen_tables2.py out/unseen9600 --first 9600 --count 30
    .venv/bin/python experiments/bench_campaign.py --real-only --data-dir out/unseen9600 \
        --generations 30 --workers 2
"""
import argparse
import json
import os

import numpy as np
import pandas as pd

FAMILIES = ["cooktorrance", "ward", "blinnphong", "hetorrance", "hapke", "layered",
            "lambertspec", "mirror", "twolobe", "orennayar"]

D = np.pi / 180.0


def fresnel_schlick(cos_i, f0):
    return f0 + (1 - f0) * (1 - np.clip(cos_i, 0, 1)) ** 5


def fresnel_dielectric(cos_i, n):
    cos_i = np.clip(cos_i, 1e-9, 1)
    sin_t2 = (1 - cos_i ** 2) / n ** 2
    cos_t = np.sqrt(np.clip(1 - sin_t2, 0, 1))
    rs = ((cos_i - n * cos_t) / (cos_i + n * cos_t)) ** 2
    rp = ((n * cos_i - cos_t) / (n * cos_i + cos_t)) ** 2
    return 0.5 * (rs + rp)


def geometry(g, t):
    """in-plane incident and outgoing directions, half vector angle etc.
    g, t in radians; g <= 0 source side; outgoing at t.  Directions in (x, z)."""
    # incident direction towards the surface comes from angle g (source at x<0 side for g<0)
    wi = np.stack([np.sin(g), np.cos(g)])          # direction to the source
    wo = np.stack([np.sin(t), np.cos(t)])          # direction to the receiver
    # mirror of wi: (-sin g, cos g) -> theta = -g
    h = wi + wo
    hn = np.linalg.norm(h, axis=0)
    h = h / np.where(hn > 0, hn, 1)
    cos_h = np.clip(h[1], 1e-9, 1)                  # angle of the half vector to the normal
    cos_d = np.clip((wi * h).sum(0), 0, 1)          # angle between wi and h
    cos_i = np.clip(np.cos(g), 1e-9, 1)
    cos_o = np.clip(np.cos(t), 0, 1)
    return cos_i, cos_o, cos_h, cos_d


def bsdf_power(fam, p, g, t):
    """radiance-like received power (receiver sees the lit spot: power ~ BRDF * cos_i * cos_o)."""
    cos_i, cos_o, cos_h, cos_d = geometry(g, t)
    phi = -g - t  # angle from mirror
    if fam == "cooktorrance":
        m = p["m"]
        tan2 = (1 - cos_h ** 2) / cos_h ** 2
        Dh = np.exp(-tan2 / m ** 2) / (np.pi * m ** 2 * cos_h ** 4)
        F = fresnel_schlick(cos_d, p["f0"])
        # Smith-ish shadowing (Cook-Torrance V-cavity)
        G = np.minimum(1, np.minimum(2 * cos_h * cos_o / cos_d, 2 * cos_h * cos_i / cos_d))
        spec = Dh * F * G / (4 * cos_i * np.maximum(cos_o, 1e-3))
        f = p["kd"] / np.pi + p["ks"] * spec
        return f * cos_i * cos_o
    if fam == "ward":
        a = p["alpha"]
        tan2 = (1 - cos_h ** 2) / cos_h ** 2
        spec = np.exp(-tan2 / a ** 2) / (4 * np.pi * a ** 2 * np.sqrt(cos_i * np.maximum(cos_o, 1e-3)))
        f = p["kd"] / np.pi + p["ks"] * spec
        return f * cos_i * cos_o
    if fam == "blinnphong":
        n = p["n"]
        F = fresnel_dielectric(cos_d, p["ior"])
        spec = (n + 8) / (8 * np.pi) * cos_h ** n * F / 0.04
        f = p["kd"] / np.pi + p["ks"] * spec
        return f * cos_i * cos_o
    if fam == "hetorrance":
        # coherent spike (Gaussian in phi, width ~ instrument) + wide incoherent lobe
        F = fresnel_dielectric(cos_i, p["ior"])
        sig_r = p["sigma_rough"]  # roughness/wavelength
        g_ = (4 * np.pi * sig_r * cos_i) ** 2
        spike = F * np.exp(-g_) * np.exp(-0.5 * (phi / (p["spike_w"] * D)) ** 2)
        tan2 = (1 - cos_h ** 2) / cos_h ** 2
        wide = F * (1 - np.exp(-g_)) * np.exp(-tan2 / p["m"] ** 2) / (np.pi * p["m"] ** 2 * cos_h ** 4) / 4
        return p["ks"] * (p["spike_amp"] * spike + wide * cos_o) + p["kd"] / np.pi * cos_i * cos_o
    if fam == "hapke":
        # Lommel-Seeliger with Henyey-Greenstein phase + shadow-hiding opposition surge
        mu0 = cos_i
        mu = cos_o
        # phase angle between source and receiver directions: |t - g|
        alpha = np.abs(t - g)
        gg = p["hg"]
        P = (1 - gg ** 2) / (1 + gg ** 2 + 2 * gg * np.cos(alpha)) ** 1.5
        B = p["B0"] / (1 + np.tan(alpha / 2) / p["h"])
        if p["ls_only"]:
            H = 1.0
            Hr = 1.0
        else:
            w = p["w"]
            gam = np.sqrt(1 - w)
            H = (1 + 2 * mu0) / (1 + 2 * gam * mu0)
            Hr = (1 + 2 * mu) / (1 + 2 * gam * mu)
        r = p["w"] / (4 * np.pi) * mu0 / (mu0 + mu + 1e-9) * ((1 + B) * P + H * Hr - 1)
        return r * mu
    if fam == "layered":
        # diffuse base under a glossy coat; coat share rises to 1 at grazing (saturating)
        share = np.minimum(1.0, p["s0"] + (1 - p["s0"]) * (1 - cos_i) ** p["q"] * p["boost"])
        n = p["n"]
        lobe = (n + 1) / (2 * np.pi) * np.clip(np.cos(phi), 0, 1) ** n
        diff = (1 - share) * cos_o / np.pi
        return p["K"] * (share * lobe + diff)
    if fam == "lambertspec":
        n = p["n"]
        lobe = (n + 1) / (2 * np.pi) * np.clip(np.cos(phi), 0, 1) ** n
        return p["K"] * ((1 - p["a"]) * cos_i * cos_o / np.pi + p["a"] * lobe)
    if fam == "mirror":
        w = p["w"] * D  # lobe HWHM-ish: Gaussian sigma
        spike = np.exp(-0.5 * (phi / w) ** 2) / (np.sqrt(2 * np.pi) * w)
        return p["K"] * (p["a"] * spike * fresnel_schlick(cos_i, 0.05) / 0.05 + (1 - p["a"]) * cos_o / np.pi)
    if fam == "twolobe":
        cg = np.cos(g)
        a_s = np.minimum(1, p["u_as"] * cg ** p["v_as"])
        nd = p["u_nd"] * cg ** p["v_nd"]
        ns = p["u_ns"] * cg ** p["v_ns"]
        def gl(c, n):
            return (n + 1) / (2 * np.pi) * np.clip(c, 0, 1) ** n

        return p["K"] * ((1 - a_s) * gl(np.cos(t), nd) + a_s * gl(np.cos(phi), ns))
    if fam == "orennayar":
        s2 = p["sigma"] ** 2
        A = 1 - 0.5 * s2 / (s2 + 0.33)
        B = 0.45 * s2 / (s2 + 0.09)
        ti, to = np.abs(g), np.abs(t)
        # in-plane: cos(phi_i - phi_o) = +1 if receiver on source side (same sign), -1 otherwise
        cphi = np.where(np.sign(t) == np.sign(g), 1.0, -1.0)
        al, be = np.maximum(ti, to), np.minimum(ti, to)
        f = p["rho"] / np.pi * (A + B * np.maximum(0, cphi) * np.sin(al) * np.tan(be))
        n = p["n"]
        lobe = (n + 1) / (2 * np.pi) * np.clip(np.cos(phi), 0, 1) ** n
        return p["K"] * (f * np.cos(g) * np.cos(t) + p["a"] * lobe)
    raise ValueError(fam)


def draw_params(fam, rng):
    u = rng.uniform
    if fam == "cooktorrance":
        return dict(m=u(0.05, 0.4), f0=u(0.02, 0.9), kd=u(0.05, 0.8), ks=u(0.2, 1.0))
    if fam == "ward":
        return dict(alpha=u(0.04, 0.35), kd=u(0.05, 0.7), ks=u(0.05, 0.6))
    if fam == "blinnphong":
        return dict(n=float(rng.choice([20, 60, 200, 800, 3000])), ior=u(1.3, 1.8), kd=u(0.1, 0.8), ks=u(0.1, 0.8))
    if fam == "hetorrance":
        return dict(ior=u(1.4, 2.5), sigma_rough=u(0.02, 0.12), spike_w=u(0.6, 2.0), spike_amp=u(0.05, 0.5),
                    m=u(0.15, 0.5), ks=1.0, kd=u(0.0, 0.3))
    if fam == "hapke":
        return dict(w=u(0.3, 0.95), hg=u(-0.5, 0.2), B0=u(0.3, 1.5), h=u(0.02, 0.2), ls_only=bool(rng.random() < 0.4))
    if fam == "layered":
        return dict(s0=u(0.03, 0.3), q=u(1.0, 3.0), boost=u(1.5, 6.0), n=float(u(30, 600)), K=1.0)
    if fam == "lambertspec":
        return dict(a=u(0.01, 0.08), n=float(u(10, 300)), K=1.0)
    if fam == "mirror":
        return dict(w=u(0.5, 2.0) / 2.3548, a=u(0.05, 0.8), K=1.0)  # FWHM 0.5..2 deg
    if fam == "twolobe":
        return dict(u_as=u(0.02, 0.4), v_as=u(-2.5, 0.5), u_nd=u(0.5, 2.5), v_nd=u(-0.5, 1.0),
                    u_ns=u(20, 400), v_ns=u(-0.6, 0.6), K=1.0)
    if fam == "orennayar":
        return dict(sigma=u(0.2, 0.6), rho=u(0.3, 0.9), a=u(0.0, 0.05), n=float(u(20, 200)), K=1.0)


def make_table(seed):
    rng = np.random.default_rng(seed)
    fam = FAMILIES[(seed - 9600) % len(FAMILIES)]
    p = draw_params(fam, rng)
    truth = dict(seed=seed, family=fam, params=p, artefacts={})
    art = truth["artefacts"]

    # ---- grid ----
    ng = int(rng.integers(2, 11))
    if fam == "mirror":
        ng = int(rng.integers(2, 5))
    gammas = np.sort(rng.choice(np.arange(0, 86), size=ng, replace=False))
    gammas = -gammas.astype(float)
    # irregular; allow a non-integer one sometimes
    if rng.random() < 0.3:
        gammas[int(rng.integers(ng))] += -round(rng.uniform(0.1, 0.9), 1)
    gammas = np.clip(gammas, -88, 0)
    if fam == "mirror":
        step = float(rng.choice([0.2, 0.25, 0.5]))
    else:
        step = float(rng.choice([0.5, 1, 2, 2.5, 3, 5, 7.5, 10]))
    lo = -float(rng.choice([90, 85, 80, 70, 60, 40, 20]))
    hi = float(rng.choice([90, 88, 85, 80, 70, 60]))
    if fam == "mirror":
        lo, hi = -float(rng.choice([30, 20, 10])), float(rng.choice([80, 70]))
    clearance = float(rng.uniform(2.5, 6))
    thetas = np.round(np.arange(lo, hi + 1e-9, step), 3)
    art.update(gammas=gammas.tolist(), step=step, theta_range=[lo, hi], clearance=clearance)

    # holes: drop 1-2 theta intervals per table sometimes
    holes = []
    if rng.random() < 0.35:
        for _ in range(int(rng.integers(1, 3))):
            c = rng.uniform(lo, hi)
            w = rng.uniform(3, 15)
            holes.append([c - w / 2, c + w / 2])
    art["holes"] = holes

    rows = []
    for gdeg in gammas:
        th = thetas[np.abs(thetas - gdeg) > clearance]
        for a, b in holes:
            th = th[(th < a) | (th > b)]
        # mirror family: dense only near mirror, coarse elsewhere (keeps table small)
        if fam == "mirror":
            keep = (np.abs(th + gdeg) < 8) | (np.isclose(np.mod(th, 5), 0))
            th = th[keep]
        if step <= 0.5 and fam != "mirror":
            keep = (np.abs(th + gdeg) < 20) | (np.isclose(np.mod(th, 2), 0))
            th = th[keep]
        for tdeg in th:
            rows.append((gdeg, tdeg))
    G = np.array([r[0] for r in rows])
    T = np.array([r[1] for r in rows])

    # ---- true power, with finite receiver aperture ----
    ap_kind = rng.choice(["none", "box", "gauss"], p=[0.4, 0.3, 0.3])
    if fam == "mirror":
        ap_kind = rng.choice(["none", "box", "gauss"], p=[0.5, 0.25, 0.25])
    ap_w = float(rng.uniform(1, 4))
    art["aperture"] = dict(kind=str(ap_kind), width_deg=ap_w if ap_kind != "none" else 0)
    if ap_kind == "none":
        P = bsdf_power(fam, p, G * D, T * D)
    else:
        if ap_kind == "box":
            off = np.linspace(-ap_w / 2, ap_w / 2, 41)
            wts = np.ones_like(off)
        else:
            off = np.linspace(-2.5 * ap_w / 2.3548, 2.5 * ap_w / 2.3548, 41)
            wts = np.exp(-0.5 * (off / (ap_w / 2.3548)) ** 2)
        wts /= wts.sum()
        P = sum(w * bsdf_power(fam, p, G * D, np.clip(T + o, -90, 90) * D) for o, w in zip(off, wts, strict=True))
    P = np.nan_to_num(np.maximum(P, 0))

    # ---- scale ----
    peak = 10 ** rng.uniform(-6, 6)
    P = P / P.max() * peak
    art["peak_power"] = float(peak)

    # gain drift between angles of incidence
    drift = 0.0
    if rng.random() < 0.4:
        drift = float(rng.uniform(0.01, 0.08))
        gains = {gd: 1 + rng.normal(0, drift) for gd in np.unique(G)}
        P = P * np.array([gains[gd] for gd in G])
    art["gain_drift_rel"] = drift

    # repeated measurements
    nrep = 1
    if rng.random() < 0.3:
        nrep = int(rng.integers(2, 4))
    art["repeats"] = nrep
    G = np.repeat(G, nrep)
    T = np.repeat(T, nrep)
    P = np.repeat(P, nrep)

    # noise: shot + gaussian
    rel = float(rng.uniform(0.003, 0.05))
    shot = rng.random() < 0.5
    if shot:
        # photon count at peak ~ 1/rel^2 -> poisson relative noise rel at peak
        nph = 1.0 / rel ** 2
        counts = rng.poisson(np.maximum(P / peak * nph, 0))
        Pn = counts / nph * peak
        floor = 0.1 * rel * peak * rng.uniform(0.02, 0.2)
        Pn = Pn + rng.normal(0, floor, P.size)
        sig = np.sqrt(np.maximum(P / peak * nph, 1)) / nph * peak
        sig = np.sqrt(sig ** 2 + floor ** 2)
    else:
        # gaussian: proportional + floor
        floor = rel * peak * rng.uniform(0.005, 0.05)
        sig = np.sqrt((rel * P) ** 2 + floor ** 2)
        Pn = P + rng.normal(0, 1, P.size) * sig
    art["noise"] = dict(kind="shot" if shot else "gaussian", rel=rel, floor=float(floor))

    # dark offset
    dark = 0.0
    if rng.random() < 0.4 and fam != "twolobe":
        dark = float(rng.uniform(0.002, 0.03) * peak)
        Pn = Pn + dark
    art["dark_offset"] = dark

    # detector clipping at peak
    clip = None
    if rng.random() < 0.25 and fam != "twolobe":
        clip = float(np.quantile(Pn, 0.97) if rng.random() < 0.5 else 0.6 * Pn.max())
        Pn = np.minimum(Pn, clip)
    art["clip_level"] = clip

    # ADC quantisation
    q = None
    if rng.random() < 0.4:
        bits = int(rng.choice([8, 10, 12]))
        full = Pn.max() * 1.05
        q = full / 2 ** bits
        Pn = np.round(Pn / q) * q
    art["adc_lsb"] = q

    df = pd.DataFrame(dict(gamma_deg=G, theta_deg=T, power=Pn))
    if rng.random() < 0.25:
        df["sigma"] = sig
        art["sigma_column"] = True
    else:
        art["sigma_column"] = False
    if rng.random() < 0.2:
        df["material"] = f"{fam}_sample_{seed}"
        art["material_column"] = True
    else:
        art["material_column"] = False
    shuffled = rng.random() < 0.4
    if shuffled:
        df = df.sample(frac=1.0, random_state=seed).reset_index(drop=True)
    art["shuffled"] = shuffled
    art["rows"] = len(df)
    return fam, df, truth


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("outdir")
    ap.add_argument("--first", type=int, default=9600)
    ap.add_argument("--count", type=int, default=30)
    a = ap.parse_args()
    os.makedirs(a.outdir, exist_ok=True)
    truths = {}
    for s in range(a.first, a.first + a.count):
        fam, df, truth = make_table(s)
        name = f"{fam}-{s}.csv"
        df.to_csv(os.path.join(a.outdir, name), index=False, float_format="%.8g")
        truths[name] = truth
    with open(os.path.join(a.outdir, "truth.json"), "w") as f:
        json.dump(truths, f, indent=1, default=float)


if __name__ == "__main__":
    main()
