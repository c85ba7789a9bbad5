"""Compile the room simulation's kernels once (or load them from numba's on-disk cache)."""

from __future__ import annotations

import warnings

import numpy as np


def warm() -> None:
    """Run both methods once on small scenes that use every compiled path (the bundled
    office: fitted glossy and matte materials, furniture, several receivers; the glossy
    test room with glossy walls, and with the paper's surface model), so that numba's
    on-disk cache holds the room kernels. ``make`` runs it after installing, as it runs
    :func:`irreflect.fitting.warm`: a first ``irreflect room`` (or a test worker) then
    loads the kernels instead of compiling them."""
    from ..data import bundled_dir
    from .engine import simulate
    from .kernels import hemisphere_integral, pack_materials, sampled_albedo
    from .scene import load_scene
    from .validation import glossy_material, glossy_room

    office = load_scene(bundled_dir() / "rooms" / "office.toml")
    office = office.with_receivers(office.receivers[:2])
    glossy = glossy_room(walls=glossy_material(0.6))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scene, brdf in ((office, "reciprocal"), (glossy, "reciprocal"),
                            (glossy_room(), "paper")):
            simulate(scene, method="recursive", bounces=3, cell_m=1.0, brdf=brdf,
                     lobe_rays=16)
            simulate(scene, method="montecarlo", bounces=3, rays=200, seed=0, brdf=brdf)
        # the energy checks' integrals (a tabulated material's albedo, the sampler's mean)
        packed = pack_materials([glossy_material(0.5)])
        gammas = np.radians([0.0, 60.0])
        hemisphere_integral(packed, 0, gammas, n_mu=8, n_az=8)
        sampled_albedo(packed, 0, gammas, 64, 0)
