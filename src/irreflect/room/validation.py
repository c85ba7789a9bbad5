"""Reference configurations and checks of the room simulation against what exists.

* :func:`barry_configuration_a`: Barry et al. (1993), configuration A: a 5 x 5 x 3 m room,
  walls and ceiling of reflectance 0.8, floor 0.3 (all Lambertian), an emitter at
  (2.5, 2.5, 3) facing down with Lambertian order 1, a receiver at (0.5, 1, 0) facing up,
  1 cm^2, 85 deg field of view.
* :func:`line_of_sight_closed_form`: Eq. 5 of the paper (Barry's h^(0)).
* :func:`one_bounce_reference`: the first-order response off a single Lambertian floor by
  numerical integration (scipy), the limit the recursive method converges to with cell size.
"""

from __future__ import annotations

import numpy as np

from .materials import lambertian
from .scene import Emitter, Receiver, Scene

C_LIGHT = 299_792_458.0


def barry_configuration_a(*, walls=0.8, floor=0.3, ceiling=0.8, receiver_fov_deg=85.0) -> Scene:
    """Barry et al. (1993), configuration A."""
    mats = {"walls": lambertian(walls, "walls"), "floor": lambertian(floor, "floor"),
            "ceiling": lambertian(ceiling, "ceiling")}
    return Scene(
        name="Barry configuration A", size=np.array([5.0, 5.0, 3.0]),
        room_materials=("walls", "walls", "walls", "walls", "floor", "ceiling"),
        materials=mats,
        emitters=(Emitter("source", np.array([2.5, 2.5, 3.0]), np.array([0.0, 0.0, -1.0]), 1.0),),
        receivers=(Receiver("receiver", np.array([0.5, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                            1e-4, receiver_fov_deg),),
    )


def line_of_sight_closed_form(emitter: Emitter, receiver: Receiver) -> tuple[float, float]:
    """Eq. 5: ``(m+1)/(2 pi) cos^m(omega) A cos(psi) / d^2`` times the emitter power (W) and
    the delay ``d / c`` (s); no obstacles."""
    v = receiver.position - emitter.position
    d = float(np.linalg.norm(v))
    cos_e = float(v @ emitter.direction) / d
    cos_r = float(-(v @ receiver.direction)) / d
    if cos_e <= 0 or cos_r <= 0 or cos_r < np.cos(np.radians(receiver.fov_deg)):
        return 0.0, d / C_LIGHT
    m = emitter.order
    return (emitter.power_w * (m + 1) / (2 * np.pi) * cos_e**m * receiver.gain_area * cos_r / d**2,
            d / C_LIGHT)


def single_floor_scene(rho=0.5, size=(4.0, 4.0, 2.5), emitter_pos=(1.2, 2.0, 2.5),
                       receiver_pos=(3.0, 1.5, 2.5)) -> Scene:
    """A room whose only reflecting surface is a Lambertian floor (everything else black),
    emitter and receiver on the ceiling facing down: the one-bounce test case."""
    mats = {"black": lambertian(0.0, "black"), "floor": lambertian(rho, "floor")}
    return Scene(
        name="single Lambertian floor", size=np.array(size, float),
        room_materials=("black", "black", "black", "black", "floor", "black"), materials=mats,
        emitters=(Emitter("source", np.array(emitter_pos, float), np.array([0.0, 0.0, -1.0]), 1.0),),
        receivers=(Receiver("receiver", np.array(receiver_pos, float), np.array([0.0, 0.0, -1.0]),
                            1e-4, 90.0),),
    )


def one_bounce_reference(scene: Scene) -> float:
    """First-order DC gain off the floor of :func:`single_floor_scene`, by numerical
    integration over the floor (``scipy.integrate.dblquad``)."""
    from scipy.integrate import dblquad  # deferred: the benchmarks' runs need not load it

    em, rx = scene.emitters[0], scene.receivers[0]
    rho = scene.materials["floor"].reflectance
    m = em.order

    def integrand(y, x):
        p = np.array([x, y, 0.0])
        v1 = p - em.position
        d1 = np.linalg.norm(v1)
        v2 = rx.position - p
        d2 = np.linalg.norm(v2)
        cos_e = (v1 @ em.direction) / d1
        cos_in = -v1[2] / d1
        cos_out = v2[2] / d2
        cos_r = -(v2 @ rx.direction) / d2
        if min(cos_e, cos_in, cos_out, cos_r) <= 0:
            return 0.0
        return ((m + 1) / (2 * np.pi) * cos_e**m * cos_in / d1**2
                * rho / np.pi * cos_out * rx.gain_area * cos_r / d2**2)

    value, _ = dblquad(integrand, 0.0, float(scene.size[0]), 0.0, float(scene.size[1]),
                       epsabs=1e-16, epsrel=1e-9)
    return value * em.power_w


#: a medium-gloss two-lobe material of our own (not fitted to any table): specular share
#: 6 % at normal incidence growing towards grazing, specular index about 60, a flattish
#: diffuse lobe; "measured" over 10-70 deg
GLOSSY_PARAMS = {"u_as": 0.06, "v_as": -2.7, "u_nd": 0.75, "v_nd": 3.0, "u_ns": 60.0,
                 "v_ns": -0.35, "K": 1.0}


def glossy_material(rho: float, name: str = "glossy", brdf: str = "reciprocal"):
    """:data:`GLOSSY_PARAMS` as a room material of diffuse reflectance ``rho``."""
    from .materials import from_model

    return from_model("two-lobe", GLOSSY_PARAMS, rho, name=name, gamma_max_deg=70.0,
                      metadata={"gamma_range_deg": [10.0, 70.0]}, brdf=brdf,
                      source="validation.GLOSSY_PARAMS (two-lobe)")


def glossy_room(floor=None, walls=None, *, receiver_facing=(0.0, 0.0, 1.0), fov_deg=85.0,
                receiver_pos=(3.0, 1.2, 0.8), emitter_pos=(1.5, 2.0, 2.6)) -> Scene:
    """A 4 x 4 x 3 m room with a glossy floor (default :func:`glossy_material` at 0.5) and
    walls (default Lambertian 0.6; pass a material for glossy walls), ceiling Lambertian 0.7,
    an order-1 emitter below the ceiling facing down and one 1 cm^2 receiver."""
    floor = floor if floor is not None else glossy_material(0.5, "floor")
    walls = walls if walls is not None else lambertian(0.6, "walls")
    mats = {"floor": floor.renamed("floor"), "walls": walls.renamed("walls"),
            "ceiling": lambertian(0.7, "ceiling")}
    facing = np.asarray(receiver_facing, float)
    return Scene(
        name="glossy room", size=np.array([4.0, 4.0, 3.0]),
        room_materials=("walls", "walls", "walls", "walls", "floor", "ceiling"), materials=mats,
        emitters=(Emitter("source", np.array(emitter_pos, float), np.array([0.0, 0.0, -1.0]), 1.0),),
        receivers=(Receiver("receiver", np.array(receiver_pos, float),
                            facing / np.linalg.norm(facing), 1e-4, fov_deg),),
    )


def swap_ready(scene: Scene) -> Scene:
    """``scene`` with its receiver given a 90 deg field of view and its emitter order 1, so
    that :meth:`Scene.swapped` is the same link backwards (the receiver's response
    ``A cos(psi)`` is an order-1 emitter's pattern up to ``A / pi``)."""
    from dataclasses import replace

    e, r = scene.emitters[0], scene.receivers[0]
    return replace(scene, emitters=(replace(e, order=1.0),), receivers=(replace(r, fov_deg=90.0),))
