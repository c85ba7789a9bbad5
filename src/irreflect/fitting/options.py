"""The settings of one fit, as one object (:class:`FitOptions`), and the search sizes
:func:`irreflect.fitting.fit` chooses by table and model."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

#: Tables of at most this many points get the search of :data:`SMALL_TABLE_SEARCH`.
SMALL_TABLE_POINTS = 40
#: The search on small tables: on the paper's 12-point protocol of each of the 11 real
#: sets, the large-table search (96 candidates, 3 kept, no hops, 3 rounds) reached the best
#: cost found in 60 of 110 fits (10 seeds per set; up to 68 % above it otherwise), this
#: one in 103 of 110, at 2-60 ms a fit (experiments/check_small_fits.py).
SMALL_TABLE_SEARCH = {"n_screen": 1000, "n_keep": 30, "n_hops": 30, "max_rounds": 8}
#: The second search of :func:`fit` when the first result looks like a local optimum (see
#: :func:`retry_reasons`): the search of :data:`SMALL_TABLE_SEARCH` on any table, and a
#: larger one on small tables (whose first search was already that one). On 2,000
#: tables of :func:`irreflect.synthetic.wild_material` (glossy, mirror-like, matte and
#: diffuse; 1 to 8 angles of incidence, steps of 1 to 20 deg; proportional and additive
#: noise, with and without sigma), the first search alone ended above the generating
#: coefficients' cost in 15, with the second search in 1; about half the tables are
#: searched twice (experiments/check_retry.py).
RETRY_SEARCH = SMALL_TABLE_SEARCH
RETRY_SMALL_TABLE_SEARCH = {"n_screen": 4000, "n_keep": 60, "n_hops": 30, "max_rounds": 8}


@dataclass(frozen=True)
class FitOptions:
    """The settings of :func:`irreflect.fitting.fit` (every one optional).

    Attributes
    ----------
    seed : int
        Seeds the random extra starts and the screening; the same seed gives the same result.
    n_random_starts : int
        Random perturbations of the first data-driven start.
    n_screen, n_keep, n_data_starts : int or None
        Number of screening candidates (default by model size, see
        :data:`~irreflect.fitting.screening.DEFAULT_SCREEN`); how many of all candidates,
        in different basins (default :func:`~irreflect.fitting.screening.default_keep`),
        and how many of the best data-driven ones start Levenberg-Marquardt.
    use_sigma : bool
        Weight by ``1 / sigma^2`` when the table has ``sigma``.
    max_iter, max_rounds : int
        Iteration limit of each local search; rounds of coordinate scans (default 3).
    polish : bool
        Finish a local search that crawled with scipy's trust-region least squares.
    engine : ``"compiled"``, ``"numpy"``, ``"numpy-first"`` or None
        The compiled kernel (the two-lobe model and its extensions) or the numpy
        reference implementation; ``"numpy-first"``: numpy, and the compiled kernel for
        the retry's second search on tables of more than
        :data:`~irreflect.fitting.engine.NUMPY_FIRST_POINTS` points; None: :data:`~irreflect.fitting.engine.ENGINE`.
    extra_starts : array (S, P) or None
        More starting points of the nonlinear coordinates, tried first (a warm start).
    n_hops : int or None
        Basin hops around the best point per round (default by model). On small tables
        (at most :data:`SMALL_TABLE_POINTS` points, a model of 4 or more shape
        coordinates: a 12-point protocol) the defaults of ``n_screen``, ``n_keep``,
        ``n_hops`` and ``max_rounds`` are those of :data:`SMALL_TABLE_SEARCH`.
    retry : bool
        Search a second time, more widely, when the result looks like a local optimum
        (:func:`~irreflect.fitting.retry_reasons`).
    """

    seed: int = 0
    n_random_starts: int = 2
    n_screen: int | None = None
    n_keep: int | None = None
    n_data_starts: int | None = None
    use_sigma: bool = True
    max_iter: int = 200
    max_rounds: int | None = None
    polish: bool = True
    engine: str | None = None
    extra_starts: np.ndarray | None = None
    n_hops: int | None = None
    retry: bool = True

    def sized_for(self, model, n_points: int) -> FitOptions:
        """These options with the search sizes left to fit() filled in: the caller's,
        else :data:`SMALL_TABLE_SEARCH` on a small table (and a model of 4 or more shape
        coordinates), else the model's defaults (None) and 3 rounds."""
        small = n_points <= SMALL_TABLE_POINTS and model.n_nonlinear >= 4
        if self.extra_starts is None:  # hashable: the same options give the same object
            return _sized(self, small)
        return _sized.__wrapped__(self, small)

    def widened(self, n_points: int, z_first=None, n_nonlinear: int = 0) -> FitOptions:
        """The second search's options (:data:`RETRY_SEARCH`, on small tables
        :data:`RETRY_SMALL_TABLE_SEARCH`; the caller's larger sizes kept), started from
        ``z_first`` (the first result's shape coordinates) too."""
        effort = RETRY_SMALL_TABLE_SEARCH if n_points <= SMALL_TABLE_POINTS else RETRY_SEARCH
        sizes = {k: v if getattr(self, k) is None else max(int(getattr(self, k)), v)
                 for k, v in effort.items()}
        if z_first is not None:
            extra = self.extra_starts
            sizes["extra_starts"] = (z_first if extra is None else np.vstack(
                [z_first, np.asarray(extra, float).reshape(-1, n_nonlinear)]))
        return dataclasses.replace(self, **sizes)


@functools.lru_cache(maxsize=64)
def _sized(opts: FitOptions, small: bool) -> FitOptions:
    """:meth:`FitOptions.sized_for` on a small table (``small``) or a large one."""
    sizes = {}
    if small:
        sizes = {k: v for k, v in SMALL_TABLE_SEARCH.items() if getattr(opts, k) is None}
    if opts.max_rounds is None and "max_rounds" not in sizes:
        sizes["max_rounds"] = 3
    return dataclasses.replace(opts, **sizes) if sizes else opts


#: The keyword settings :func:`~irreflect.fitting.fit` accepts (FitOptions' fields).
FIT_SETTINGS = tuple(f.name for f in dataclasses.fields(FitOptions))
