"""Every figure irreflect draws (matplotlib lives here and in :mod:`irreflect.report` only).

Modules: :mod:`.common` (the backend, :func:`save_figure`, polar diagrams, the 3D surface,
residual maps and histograms and their robust limits), then one module per capability:
:mod:`.selection` (Pareto frontier, chosen points), :mod:`.protocol` (protocol points),
:mod:`.compare` (model comparison), :mod:`.diagnose` (residual maps and polar fits of a
diagnosis), :mod:`.room` (impulse responses, DC gains, maps, 3D materials). Every
``plot_*`` draws on the axes or figure it is given (or makes one) and returns it.
"""

from .common import (
    NORMALIZED,
    plot_polar,
    plot_polar_per_gamma,
    plot_residual_histogram,
    plot_residual_map,
    plot_surface,
    plt,
    robust_limit,
    robust_limits,
    save_figure,
)

__all__ = ["NORMALIZED", "plot_polar", "plot_polar_per_gamma", "plot_residual_histogram",
           "plot_residual_map", "plot_surface", "plt", "robust_limit", "robust_limits",
           "save_figure"]
