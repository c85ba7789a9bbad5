"""Room simulation: line of sight exactly, reflections by Barry's recursive method or by
modified Monte Carlo with next-event estimation, for every emitter-receiver pair.

**Recursive method** (Barry et al. 1993, on cells of about ``cell_m``): the light arriving at
every cell after one reflection is computed once per emitter (a pass over all cell pairs,
with exact delay moments and phase); per receiver, a second pass over all cell pairs gives
what a unit power arriving at each cell delivers to the receiver after two more reflections.
Orders 1 and 2 are accumulated directly; order ``k >= 3`` is the per-cell convolution of the
two (meet in the middle, by FFT), after ``k - 3`` more cell-to-cell legs for ``k >= 4``. No
cell-by-cell matrix is ever stored: memory is O(cells x time bins). Exact for Lambertian
surfaces (up to the cell discretisation); for other materials orders 1 and 2 use the exact
incidence direction at every reflection, and from order 3 on the reflection at the middle
cells uses the power-weighted mean incidence direction of the once-reflected light arriving
there (Monte Carlo has no such approximation). Delay moments, DC gains and phases are exact
sums over cell paths; ``h(t)`` of order >= 3 is binned twice (within one bin).

**Monte Carlo** (Lopez-Hernandez et al. 2000): rays from the emitter; at every hit the
deterministic contribution of the hit point to the receiver is added (next-event
estimation), then a new direction is drawn from the material's lobes. Any material, any
number of bounces; per-bounce standard errors. Seeded per emitter-receiver pair
(``SeedSequence(seed, spawn_key=(emitter, receiver))``), so serial, process-pool and Dask runs
give identical results.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import multiprocessing as mp
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from .._progress import progress as progress_display
from ..errors import IrreflectError
from . import kernels as K
from .checks import DEFAULTS, check_room_budget, check_simulate_arguments
from .geometry import (
    Cells,
    boxes_array,
    cells_to_receiver,
    discretize,
    emitter_to_cells,
    face_material_indices,
    line_of_sight,
)
from .results import summary_table, write_results
from .scene import METHODS, Scene

#: receivers per task of a process pool or Dask cluster (fixed: results do not depend on it)
TASK_RECEIVERS = 8
_CHUNK = 16  # cells per chunk of the backward pass (per-chunk buffers, thread-independent)


@dataclass
class LinkResult:
    """One emitter-receiver pair. Index 0 of every per-order array is the line of sight,
    index ``k`` the ``k``-th reflection.

    power_w : (K+1,) received power per order (W)
    m1, m2 : (K+1,) sums of power x delay (W s) and power x delay^2 (W s^2)
    phasor : (K+1,) complex, sum of power x exp(-j 2 pi f tau) at the emitter's modulation
    stderr_w : (K+1,) standard error of ``power_w`` (Monte Carlo; 0 when exact)
    hist : (K+1, T) received power per delay bin (W)
    reflected_w : (K,) power left after k reflections, all surfaces together (W)
    """

    emitter: int
    receiver: int
    power_w: np.ndarray
    m1: np.ndarray
    m2: np.ndarray
    phasor: np.ndarray
    stderr_w: np.ndarray
    hist: np.ndarray
    reflected_w: np.ndarray
    los_delay_s: float
    seconds: float = 0.0
    kernel_seconds: float = 0.0


@dataclass
class RoomResult:
    """Results of :func:`simulate` for every emitter-receiver pair (see :mod:`.results`)."""

    scene: Scene
    method: str
    bounces: int
    cell_m: float | None
    rays: int | None
    seed: int
    dt_s: float
    links: dict = field(default_factory=dict)
    n_cells: int = 0
    seconds: float = 0.0
    ray_bounces_per_s: float | None = None
    notes: list = field(default_factory=list)

    def link(self, emitter=0, receiver=0) -> LinkResult:
        e = self._index(emitter, [x.name for x in self.scene.emitters], "emitter")
        r = self._index(receiver, [x.name for x in self.scene.receivers], "receiver")
        return self.links[(e, r)]

    @staticmethod
    def _index(key, names, kind):
        if isinstance(key, int | np.integer):
            return int(key)
        if key not in names:
            raise IrreflectError(f"no {kind} named '{key}'")
        return names.index(key)

    @property
    def time_ns(self) -> np.ndarray:
        any_link = next(iter(self.links.values()))
        return np.arange(any_link.hist.shape[1]) * self.dt_s * 1e9

    def summary(self):
        return summary_table(self)

    def write(self, out_dir, figures=None) -> list[str]:
        """Every number as CSV and Parquet into ``out_dir``; the figures too with
        ``figures=irreflect.plots.room.write_figures`` (see :func:`.results.write_results`)."""
        return write_results(self, out_dir, figures=figures)


# ----------------------------------------------------------------------------- shared context
@dataclass
class _Context:
    scene: Scene
    method: str
    bounces: int
    dt: float
    n_bins: int
    rays: int
    seed: int
    mats: tuple
    cells: Cells | None = None
    boxes: np.ndarray | None = None
    general: bool = False
    emitter_states: dict = field(default_factory=dict)
    threads: int = 1


def _resolve(scene: Scene, **overrides) -> dict:
    s = dict(DEFAULTS)
    s.update(scene.settings)
    s.update({k: v for k, v in overrides.items() if v is not None})
    if s["method"] not in METHODS:
        raise IrreflectError(f"method must be one of {', '.join(METHODS)}; found '{s['method']}'")
    for key, lo in (("bounces", 0), ("rays", 1), ("seed", 0)):
        v = s[key]
        if not isinstance(v, int | np.integer) or v < lo:
            raise IrreflectError(f"{key} must be an integer >= {lo}; found {v!r}")
    if s["bounces"] > 50:
        raise IrreflectError(f"bounces must be at most 50; found {s['bounces']}")
    for key in ("cell_m", "time_resolution_ns"):
        if not (isinstance(s[key], int | float) and s[key] > 0 and math.isfinite(s[key])):
            raise IrreflectError(f"{key} must be a number > 0; found {s[key]!r}")
    if s["cell_m"] > float(min(scene.size)):
        raise IrreflectError(f"cell size {s['cell_m']:g} m is larger than the room's smallest "
                             f"side {float(min(scene.size)):g} m: use a smaller --cell")
    return s


def simulate(scene: Scene, *, method=None, bounces=None, cell_m=None, rays=None, seed=None,
             time_resolution_ns=None, scheduler=None, workers: int | None = None,
             threads: int | None = None, progress: bool = False) -> RoomResult:
    """Impulse response, DC gain, delays and phase for every emitter-receiver pair.

    Parameters
    ----------
    scene : Scene
        From :func:`~irreflect.room.load_scene` or built in Python.
    method : "recursive" or "montecarlo"
        Default: the scene's ``[simulation]`` method, else ``montecarlo``.
    bounces : int
        Reflections to follow (0 = line of sight only). Default 3.
    cell_m : float
        Cell size of the recursive method (m). Default 0.25.
    rays : int
        Rays per emitter-receiver pair (Monte Carlo). Default 20000.
    seed : int
        Seed of the Monte Carlo rays. Default 0.
    time_resolution_ns : float
        Width of the h(t) bins (ns). Default 0.25.
    scheduler : str or distributed.Client, optional
        Spread the receivers over a Dask cluster.
    workers : int, optional
        Local worker processes for the receivers (default 1: this process).
    threads : int, optional
        Threads of the recursive passes within one process (default: CPU count, 1 in workers).
    progress : bool
        Show a progress bar on stderr.
    """
    check_simulate_arguments(scene, scheduler, workers, threads)
    s = _resolve(scene, method=method, bounces=bounces, cell_m=cell_m, rays=rays, seed=seed,
                 time_resolution_ns=time_resolution_ns)
    check_room_budget(scene, s, workers=workers)  # refused before any work when too large
    t0 = time.perf_counter()
    _, mats = scene.material_list()
    dt = s["time_resolution_ns"] * 1e-9
    K_ = int(s["bounces"])
    n_bins = int(math.ceil((K_ + 1) * scene.diagonal / K.C_LIGHT / dt)) + 2
    ctx = _Context(scene, s["method"], K_, dt, n_bins, int(s["rays"]), int(s["seed"]),
                   K.pack_materials(mats), boxes=boxes_array(scene),
                   general=any(not m.is_lambertian for m in mats),
                   threads=threads or os.cpu_count() or 1)
    result = RoomResult(scene, s["method"], K_, s["cell_m"] if s["method"] == "recursive" else None,
                        s["rays"] if s["method"] == "montecarlo" else None, int(s["seed"]), dt)
    pairs = [(e, r) for e in range(len(scene.emitters)) for r in range(len(scene.receivers))]
    bar = None
    if progress:

        bar = progress_display(total=len(pairs), desc=f"room ({s['method']})", unit="link")
    try:
        if s["method"] == "recursive" and K_ >= 1:
            ctx.cells = discretize(scene, s["cell_m"])
            result.n_cells = ctx.cells.n
            if K_ >= 3:
                for e in range(len(scene.emitters)):
                    if bar is not None:
                        bar.set_postfix_str(f"bounce-1 light of {scene.emitters[e].name}")
                    ctx.emitter_states[e] = _emitter_state(ctx, e)
            if ctx.general and K_ >= 3:
                result.notes.append(
                    "recursive method with non-Lambertian materials: orders 1-2 exact, from order "
                    "3 on the middle reflections use the mean incidence direction per cell "
                    "(Monte Carlo is exact for any material)")
        links = _run(ctx, pairs, scheduler, workers, bar)
    finally:
        if bar is not None:
            bar.close()
    result.links = {(lk.emitter, lk.receiver): lk for lk in links}
    result.seconds = time.perf_counter() - t0
    if s["method"] == "montecarlo" and K_ >= 1:
        busy = sum(lk.kernel_seconds for lk in links)
        result.ray_bounces_per_s = len(links) * ctx.rays * K_ / busy if busy > 0 else None
    return result


# ----------------------------------------------------------------------------- execution
def _run(ctx, pairs, scheduler, workers, bar):
    tasks = [pairs[i:i + TASK_RECEIVERS] for i in range(0, len(pairs), TASK_RECEIVERS)]
    out = []

    def tick(n):
        if bar is not None:
            bar.update(n)

    if scheduler is not None:
        return _run_dask(ctx, tasks, scheduler, tick)
    n_workers = min(int(workers or 1), len(tasks))
    if n_workers <= 1:
        for task in tasks:
            out.extend(_run_task(ctx, task))
            tick(len(task))
        return out

    results = {}
    wctx = _worker_copy(ctx)
    with cf.ProcessPoolExecutor(max_workers=n_workers, mp_context=mp.get_context("forkserver"),
                                initializer=_init_worker, initargs=(wctx,)) as pool:
        futures = {pool.submit(_run_task_global, t): i for i, t in enumerate(tasks)}
        for fut in cf.as_completed(futures):
            results[futures[fut]] = fut.result()
            tick(len(tasks[futures[fut]]))
    for i in range(len(tasks)):
        out.extend(results[i])
    return out


def _worker_copy(ctx: _Context) -> _Context:

    return replace(ctx, threads=1)


_WORKER_CTX: _Context | None = None


def _init_worker(ctx):
    global _WORKER_CTX
    _WORKER_CTX = ctx


def _run_task_global(task):
    return _run_task(_WORKER_CTX, task)


def _run_dask(ctx, tasks, scheduler, tick):
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise IrreflectError("--scheduler needs dask.distributed") from exc
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout="10s") if own else scheduler
    except OSError as exc:
        raise IrreflectError(
            f"cannot reach the Dask scheduler at '{scheduler}' ({exc}): start one with "
            "'dask scheduler' or leave out --scheduler to run locally") from exc
    try:
        shared = client.scatter(_worker_copy(ctx), broadcast=True)
        futures = [client.submit(_run_task, shared, t, pure=False) for t in tasks]
        index = {f.key: i for i, f in enumerate(futures)}
        results = {}
        for fut in as_completed(futures):
            i = index[fut.key]
            results[i] = fut.result()
            tick(len(tasks[i]))
    finally:
        if own:
            client.close()
    return [lk for i in range(len(tasks)) for lk in results[i]]


def _run_task(ctx: _Context, task) -> list[LinkResult]:
    out = []
    for e, r in task:
        t0 = time.perf_counter()
        if ctx.method == "montecarlo":
            link = _montecarlo_link(ctx, e, r)
        else:
            link = _recursive_link(ctx, e, r)
        link.seconds = time.perf_counter() - t0
        out.append(link)
    return out


def _los(ctx, e, r, hist, power, m1, m2, phasor):
    em, rx = ctx.scene.emitters[e], ctx.scene.receivers[r]
    p, tau = line_of_sight(ctx.scene, em, rx)
    omega = 2 * np.pi * em.modulation_hz
    if p > 0:
        b = int(tau / ctx.dt)
        if b < hist.shape[1]:
            hist[0, b] += p
    power[0], m1[0], m2[0] = p, p * tau, p * tau * tau
    phasor[0] = p * np.exp(-1j * omega * tau)
    return tau


# ----------------------------------------------------------------------------- Monte Carlo
def link_seed(seed: int, emitter: int, receiver: int) -> int:
    """The 32-bit seed of one emitter-receiver pair (independent of how work is split)."""
    ss = np.random.SeedSequence(int(seed), spawn_key=(int(emitter), int(receiver)))
    return int(ss.generate_state(1, np.uint32)[0])


def _montecarlo_link(ctx: _Context, e: int, r: int) -> LinkResult:
    scene = ctx.scene
    em, rx = scene.emitters[e], scene.receivers[r]
    Kb = ctx.bounces
    hist = np.zeros((Kb + 1, ctx.n_bins))
    power, m1, m2 = np.zeros(Kb + 1), np.zeros(Kb + 1), np.zeros(Kb + 1)
    phasor = np.zeros(Kb + 1, complex)
    stderr = np.zeros(Kb + 1)
    reflected = np.zeros(Kb)
    tau_los = _los(ctx, e, r, hist, power, m1, m2, phasor)
    if Kb >= 1:
        h = np.zeros((Kb, ctx.n_bins))
        mom = np.zeros((Kb, 3))
        ph = np.zeros((Kb, 2))
        sumsq = np.zeros(Kb)
        room_mat, box_mat = face_material_indices(scene)
        _warm_tracer(ctx, em, rx, room_mat, box_mat, Kb)
        t0 = time.perf_counter()
        K.trace_rays(link_seed(ctx.seed, e, r), ctx.rays, em.position, em.direction,
                     float(em.order), float(em.power_w), rx.position, rx.direction,
                     float(rx.gain_area), float(np.cos(np.radians(rx.fov_deg))),
                     np.asarray(scene.size, float), ctx.boxes, room_mat, box_mat, ctx.mats, Kb,
                     ctx.dt, 2 * np.pi * em.modulation_hz, h, mom, ph, sumsq, reflected)
        kernel_s = time.perf_counter() - t0
        hist[1:] = h
        power[1:], m1[1:], m2[1:] = mom[:, 0], mom[:, 1], mom[:, 2]
        phasor[1:] = ph[:, 0] + 1j * ph[:, 1]
        stderr[1:] = np.sqrt(np.maximum(sumsq - mom[:, 0] ** 2 / ctx.rays, 0.0))
    link = LinkResult(e, r, power, m1, m2, phasor, stderr, hist.astype(np.float32), reflected,
                      tau_los)
    link.kernel_seconds = kernel_s if Kb >= 1 else 0.0
    return link


_TRACER_READY = False


def _warm_tracer(ctx, em, rx, room_mat, box_mat, Kb):
    """Load the compiled tracer once per process (so that ray rates exclude it)."""
    global _TRACER_READY
    if _TRACER_READY:
        return
    K.trace_rays(0, 1, em.position, em.direction, float(em.order), 1.0, rx.position,
                 rx.direction, 1e-4, 0.0, np.asarray(ctx.scene.size, float), ctx.boxes, room_mat,
                 box_mat, ctx.mats, Kb, ctx.dt, 0.0, np.zeros((Kb, 4)), np.zeros((Kb, 3)),
                 np.zeros((Kb, 2)), np.zeros(Kb), np.zeros(Kb))
    _TRACER_READY = True


# ----------------------------------------------------------------------------- recursive
def _bins(ctx, legs: int) -> int:
    return int(math.ceil(legs * ctx.scene.diagonal / K.C_LIGHT / ctx.dt)) + legs + 2


def _in_chunks(n, threads, fn, size=None):
    """Run ``fn(start, stop)`` over [0, n) in chunks, on ``threads`` threads (nogil kernels)."""
    size = size or max(1, min(256, -(-n // (4 * max(threads, 1)))))
    bounds = [(i, min(i + size, n)) for i in range(0, n, size)]
    if threads <= 1 or len(bounds) == 1:
        for a, b in bounds:
            fn(a, b)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(lambda ab: fn(*ab), bounds))


@dataclass
class _EmitterState:
    epow: np.ndarray
    etau: np.ndarray
    edir: np.ndarray
    omega: float
    orders: list = field(default_factory=list)  # [(hist, mom, ph)] for light after 1, 2, ... reflections
    ubar: np.ndarray | None = None
    prep_u: tuple | None = None  # lobes of every cell prepared for the incidence ubar


def _emitter_state(ctx: _Context, e: int) -> _EmitterState:
    cells = ctx.cells
    em = ctx.scene.emitters[e]
    epow, etau, edir = emitter_to_cells(ctx.scene, em, cells)
    st = _EmitterState(epow, etau, np.ascontiguousarray(edir), 2 * np.pi * em.modulation_hz)
    if ctx.bounces < 3:
        return st
    N = cells.n
    hist = np.zeros((N, _bins(ctx, 2)), np.float32)
    mom = np.zeros((N, 3))
    ph = np.zeros((N, 2))
    ubar = np.zeros((N, 3))

    if ctx.general:
        prep_e = K.prepare_cells(ctx.mats, cells.material, cells.normal, st.edir)

        def run(a, b):
            K.forward_cells(a, b, cells.pos, cells.normal, cells.area, cells.material, epow, etau,
                            st.edir, ctx.boxes, ctx.mats, prep_e, ctx.dt, st.omega, hist, mom,
                            ph, ubar)
    else:
        ubar[:] = -cells.normal
        crho = ctx.mats[1][cells.material]

        def run(a, b):
            K.forward_cells_lambertian(a, b, cells.pos, cells.normal, cells.area, crho, epow,
                                       etau, ctx.boxes, ctx.dt, st.omega, hist, mom, ph)

    _in_chunks(N, ctx.threads, run)
    st.ubar = ubar
    st.prep_u = K.prepare_cells(ctx.mats, cells.material, cells.normal, ubar)
    st.orders.append((hist, mom, ph))
    for m in range(2, ctx.bounces - 1):  # light after m reflections, for orders m + 2
        hin, momin, phin = st.orders[-1]
        hout = np.zeros((N, _bins(ctx, m + 1)), np.float32)
        momout = np.zeros((N, 3))
        phout = np.zeros((N, 2))

        def prop(a, b, hin=hin, momin=momin, phin=phin, hout=hout, momout=momout, phout=phout):
            K.propagate_cells(a, b, cells.pos, cells.normal, cells.area, cells.material, ubar,
                              ctx.boxes, ctx.mats, st.prep_u, ctx.dt, st.omega, hin, momin, phin,
                              hout, momout, phout)

        _in_chunks(N, ctx.threads, prop)
        st.orders.append((hout, momout, phout))
    return st


def _recursive_link(ctx: _Context, e: int, r: int) -> LinkResult:
    scene = ctx.scene
    Kb = ctx.bounces
    T = ctx.n_bins
    hist = np.zeros((Kb + 1, T))
    power, m1, m2 = np.zeros(Kb + 1), np.zeros(Kb + 1), np.zeros(Kb + 1)
    phasor = np.zeros(Kb + 1, complex)
    reflected = np.full(Kb, np.nan)
    tau_los = _los(ctx, e, r, hist, power, m1, m2, phasor)
    if Kb == 0:
        return LinkResult(e, r, power, m1, m2, phasor, np.zeros(Kb + 1),
                          hist.astype(np.float32), reflected, tau_los)
    cells = ctx.cells
    N = cells.n
    st = ctx.emitter_states.get(e)
    if st is None:
        st = _emitter_state(ctx, e)
    rx = scene.receivers[r]
    rgain, rtau, rdir = cells_to_receiver(scene, rx, cells)
    rdir = np.ascontiguousarray(rdir)
    omega = st.omega
    # order 1
    h1 = np.zeros(T)
    s = K.first_bounce(cells.normal, cells.material, st.epow, st.etau, st.edir, rgain, rtau,
                       rdir, ctx.mats, ctx.dt, omega, h1)
    hist[1] = h1
    power[1], m1[1], m2[1] = s[0], s[1], s[2]
    phasor[1] = s[3] + 1j * s[4]
    reflected[0] = float(np.sum(st.epow * _rho_at(ctx, cells, st.edir)))
    if Kb >= 2:
        nB = _bins(ctx, 2)
        histB = np.zeros((N, nB), np.float32)
        momB = np.zeros((N, 3))
        phB = np.zeros((N, 2))
        n_chunks = -(-N // _CHUNK)
        h2 = np.zeros((n_chunks, T))
        h2mom = np.zeros((n_chunks, 3))
        h2ph = np.zeros((n_chunks, 2))
        ubar = st.ubar if st.ubar is not None else -cells.normal

        if ctx.general:
            prep_u = st.prep_u if st.prep_u is not None else K.prepare_cells(
                ctx.mats, cells.material, cells.normal, np.ascontiguousarray(ubar))
            prep_e = K.prepare_cells(ctx.mats, cells.material, cells.normal, st.edir)
            ubar = np.ascontiguousarray(ubar)

            def run(a, b):
                K.backward_cells(a, b, _CHUNK, cells.pos, cells.normal, cells.area,
                                 cells.material, rgain, rtau, rdir, ubar, st.epow, st.etau,
                                 st.edir, ctx.boxes, ctx.mats, prep_u, prep_e, ctx.dt, omega,
                                 ctx.general, histB, momB, phB, h2, h2mom, h2ph)
        else:
            crho = ctx.mats[1][cells.material]
            rlam = rgain * crho * np.clip(np.einsum("ij,ij->i", cells.normal, rdir), 0, None) / np.pi

            def run(a, b):
                K.backward_cells_lambertian(a, b, cells.pos, cells.normal, cells.area, crho, rlam,
                                            rtau, ctx.boxes, ctx.dt, omega, histB, momB, phB)

        if ctx.general:
            _in_chunks(n_chunks, ctx.threads, run,
                       size=max(1, min(64, -(-n_chunks // (4 * ctx.threads)))))
            hist[2] = h2.sum(axis=0)
            power[2], m1[2], m2[2] = h2mom.sum(axis=0)
            p2 = h2ph.sum(axis=0)
            phasor[2] = p2[0] + 1j * p2[1]
        else:
            # emitter -> j -> l -> receiver: the emitter's light at j shifted through histB
            _in_chunks(N, ctx.threads, run)
            h2row = np.zeros(T)
            K.shift_add(h2row, histB, st.epow, (st.etau / ctx.dt).astype(np.int64))
            hist[2] = h2row
            ep, et = st.epow, st.etau
            b0, b1, b2 = momB[:, 0], momB[:, 1], momB[:, 2]
            power[2] = np.sum(ep * b0)
            m1[2] = np.sum(ep * (b1 + et * b0))
            m2[2] = np.sum(ep * (b2 + 2 * et * b1 + et * et * b0))
            phasor[2] = np.sum(ep * np.exp(-1j * omega * et) * (phB[:, 0] + 1j * phB[:, 1]))
        for k in range(3, Kb + 1):
            hin, momin, phin = st.orders[k - 3]
            reflected[k - 2] = float(np.sum(momin[:, 0] * _rho_at(ctx, cells, ubar)))
            hist[k] = _convolve_sum(hin, histB, T)
            a0, a1, a2 = momin[:, 0], momin[:, 1], momin[:, 2]
            b0, b1, b2 = momB[:, 0], momB[:, 1], momB[:, 2]
            power[k] = np.sum(a0 * b0)
            m1[k] = np.sum(a1 * b0 + a0 * b1)
            m2[k] = np.sum(a2 * b0 + 2 * a1 * b1 + a0 * b2)
            phasor[k] = np.sum((phin[:, 0] + 1j * phin[:, 1]) * (phB[:, 0] + 1j * phB[:, 1]))
    return LinkResult(e, r, power, m1, m2, phasor, np.zeros(Kb + 1), hist.astype(np.float32),
                      reflected, tau_los)


def _rho_at(ctx, cells, din):
    """Total reflectance of each cell for light arriving along ``din`` (N, 3)."""
    cos_g = np.clip(-np.einsum("ij,ij->i", din, cells.normal), 0.0, 1.0)
    g = np.arccos(cos_g)
    rhotab = ctx.mats[7]

    out = np.empty(cells.n)
    for m in np.unique(cells.material):
        sel = cells.material == m
        out[sel] = np.interp(g[sel], K.GAMMA_NODES, rhotab[m])
    return out


def _convolve_sum(a, b, T, chunk: int = 256) -> np.ndarray:
    """``sum_j conv(a[j], b[j])`` truncated to T bins, by FFT in chunks of cells."""
    n = a.shape[1] + b.shape[1] - 1
    nfft = 1 << (n - 1).bit_length()
    acc = np.zeros(nfft // 2 + 1, complex)
    for i in range(0, a.shape[0], chunk):
        fa = np.fft.rfft(a[i:i + chunk].astype(np.float64), nfft, axis=1)
        fb = np.fft.rfft(b[i:i + chunk].astype(np.float64), nfft, axis=1)
        acc += np.einsum("ij,ij->j", fa, fb)
    full = np.fft.irfft(acc, nfft)[:n]
    out = np.zeros(T)
    m = min(T, n)
    out[:m] = full[:m]
    return np.where(np.abs(out) < 1e-12 * max(np.abs(out).max(), 1e-300), 0.0, out)


__all__ = ["simulate", "RoomResult", "LinkResult", "link_seed", "DEFAULTS"]
