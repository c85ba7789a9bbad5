"""Room multipath from fitted materials: impulse response, DC gain, delay spread and the
range error of phase-based ranging, in a room of known geometry.

    from irreflect.room import load_scene, simulate
    scene = load_scene("datasets/rooms/office.toml")
    result = simulate(scene, method="montecarlo", bounces=3, rays=20000, seed=0)
    result.summary()            # one row per emitter-receiver pair
    result.write("out/room")    # CSV / Parquet of every number
    result.write("out/room", figures=irreflect.plots.room.write_figures)  # and the figures

Modules: :mod:`.materials` (the surface models of the fitted materials and material files),
:mod:`.reciprocal` (the reciprocal lobe family they are fitted to), :mod:`.checks` (what a
scene's materials say of themselves), :mod:`.scene` (TOML scenes), :mod:`.geometry` (cells,
line of sight), :mod:`.engine` (``simulate``: both methods, the error estimate),
:mod:`.recursive` and :mod:`.transport` (the receiver-independent recursive method),
:mod:`.kernels` (compiled reflection and Monte Carlo kernels), :mod:`.results` (metrics,
files), :mod:`.validation` (closed forms, Barry's configuration A, the glossy test rooms).
The command ``irreflect room``: :mod:`irreflect.cli.room`; figures:
:mod:`irreflect.plots.room`; the ``reproduce --scene`` section: :mod:`irreflect.report.room`.
"""

import importlib

_EXPORTS = {
    "Material": "materials", "from_model": "materials", "lambertian": "materials",
    "load_material": "materials", "save_material": "materials",
    "Scene": "scene", "Emitter": "scene", "Receiver": "scene", "Box": "scene", "Grid": "scene",
    "load_scene": "scene", "scene_from_dict": "scene",
    "simulate": "engine", "RoomResult": "engine", "LinkResult": "engine",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
    # lazy: `irreflect fit --save` needs the material files, not the compiled kernels
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
