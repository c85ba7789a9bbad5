"""Room simulation: line of sight exactly, reflections by Barry's recursive method or by
modified Monte Carlo with next-event estimation, for every emitter-receiver pair.

**Recursive method** (Barry et al. 1993, on cells of about ``cell_m``), receiver-independent
(:mod:`.recursive`): the light arriving at every cell after 0, 1, ..., K-1 reflections is
carried once per emitter, with exact delay moments and phases, the separable diffuse part
of every material exactly and its lobes through per-cell maps of the directions the light
came from; each receiver then gathers one more leg per order. Near cell pairs are
integrated (Gauss points, exact Lambertian form factors), far groups of cells act as one
source (a quadtree), and cells across a receiver's field-of-view edge are split. The error
of each order is estimated against a coarser run (:attr:`RoomResult.error_estimate`).

**Monte Carlo** (Lopez-Hernandez et al. 2000): rays from the emitter; at every hit the
deterministic contribution of the hit point to the receiver is added (next-event
estimation), then a new direction is drawn from the material and the ray's weight is
multiplied by the evaluated ``f cos / pdf``. Any material, any number of bounces; per-bounce
standard errors. Seeded per emitter-receiver pair (``SeedSequence(seed, spawn_key=(emitter,
receiver))``), so serial, process-pool and Dask runs give identical results.

Both methods use the scene's materials as built: the reciprocal surface model by default,
the paper's form with ``brdf="paper"`` (:mod:`.materials`).
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import multiprocessing as mp
import os
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .._progress import progress as progress_display
from ..errors import IrreflectError
from . import kernels as K
from . import recursive as R
from .checks import DEFAULTS, check_room_budget, check_simulate_arguments
from .geometry import boxes_array, face_material_indices, line_of_sight
from .materials import check_brdf
from .results import summary_table, write_results
from .scene import METHODS, Scene

#: receivers per task of a process pool or Dask cluster (fixed: results do not depend on it)
TASK_RECEIVERS = 8
#: the recursive method's error estimate: the same run at this multiple of the cell size
ESTIMATE_COARSEN = 2.0
#: a recursive order whose estimated error exceeds this gets a printed note
ERROR_NOTE = 0.01
#: an order carrying less than this share of a link's power is left out of the worst
#: estimated error: its relative error says nothing about the link (a narrow beam's first
#: reflection of 1e-34 W against 5e-7 W read 2e7 % and asked for smaller cells)
NEGLIGIBLE_SHARE = 1e-6


@dataclass
class LinkResult:
    """One emitter-receiver pair. Index 0 of every per-order array is the line of sight,
    index ``k`` the ``k``-th reflection.

    power_w : (K+1,) received power per order (W)
    m1, m2 : (K+1,) sums of power x delay (W s) and power x delay^2 (W s^2)
    phasor : (K+1,) complex, sum of power x exp(-j 2 pi f tau) at the emitter's modulation
    stderr_w : (K+1,) standard error of ``power_w`` (Monte Carlo; 0 when exact; NaN for an
        order that no ray reached, whose power 0 is then not resolved, see ``RoomResult.notes``)
    hist : (K+1, T) received power per delay bin (W); bin ``b`` covers delays
        ``[b dt, (b + 1) dt)`` (its start is ``b dt``)
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
    """Results of :func:`simulate` for every emitter-receiver pair (see :mod:`.results`).

    ``error_estimate`` (recursive method): per emitter-receiver pair, the estimated relative
    error of each order (0 for the line of sight), from a run at twice the cell size
    (Richardson: ``|H(h) - H(2h)| / 3``, the method converging as h^2) plus, with glossy
    materials, how much that run changes with a quarter of the lobe rays (an error that
    does not shrink with the cell size), or None.
    """

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
    brdf: str = "reciprocal"
    error_estimate: dict | None = None

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
        """The start of each delay bin (ns)."""
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
    geo: R.Geometry | None = None
    boxes: np.ndarray | None = None
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
             time_resolution_ns=None, brdf=None, scheduler=None, workers: int | None = None,
             threads: int | None = None, progress: bool = False,
             estimate_error: bool = True, lobe_rays: int | None = None) -> RoomResult:
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
    brdf : "reciprocal" or "paper", optional
        Rebuild the scene's fitted materials in this surface model (default: as built,
        which is "reciprocal" unless the scene says otherwise).
    scheduler : str or distributed.Client, optional
        Spread the receivers over a Dask cluster.
    workers : int, optional
        Local worker processes for the receivers (default 1: this process).
    threads : int, optional
        Threads of the recursive method within one process (default: CPU count).
    progress : bool
        Show a progress bar on stderr.
    estimate_error : bool
        Recursive method: estimate each order's error from a run at twice the cell size,
        and with glossy materials from that run again with a quarter of the lobe rays
        (default True; about a tenth of the run's time, a fifth with glossy materials).
    lobe_rays : int, optional
        Recursive method: rays per glossy cell that carry its once-reflected emitter light
        (default :data:`~.recursive.LOBE_RAYS`).
    """
    check_simulate_arguments(scene, scheduler, workers, threads)
    want = brdf or scene.settings.get("brdf")
    if want is not None:
        scene = scene.with_brdf(check_brdf(want))
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
                   threads=threads or os.cpu_count() or 1)
    kinds = {m.brdf for m in mats if not m.is_lambertian}
    result = RoomResult(scene, s["method"], K_, s["cell_m"] if s["method"] == "recursive" else None,
                        s["rays"] if s["method"] == "montecarlo" else None, int(s["seed"]), dt,
                        brdf="paper" if "paper" in kinds else "reciprocal")
    pairs = [(e, r) for e in range(len(scene.emitters)) for r in range(len(scene.receivers))]
    bar = None
    if progress:
        bar = progress_display(total=len(pairs), desc=f"room ({s['method']})", unit="link")
    try:
        if s["method"] == "recursive" and K_ >= 1:
            ctx.geo = R.prepare(scene, s["cell_m"], ctx.boxes)
            result.n_cells = ctx.geo.n
            for e in range(len(scene.emitters)):
                if bar is not None:
                    bar.set_postfix_str(f"light of {scene.emitters[e].name} over the cells")
                ctx.emitter_states[e] = R.emitter_state(ctx.geo, scene.emitters[e], K_, dt,
                                                        n_bins, ctx.threads,
                                                        lobe_rays=lobe_rays)
        links = _run(ctx, pairs, scheduler, workers, bar)
    finally:
        if bar is not None:
            bar.close()
    result.links = {(lk.emitter, lk.receiver): lk for lk in links}
    if s["method"] == "recursive" and K_ >= 1 and estimate_error:
        result.error_estimate = _error_estimate(scene, s, result, ctx.threads)
        worst = worst_error_estimate(result)
        high = {k: v for k, v in enumerate(worst) if k >= 1 and v > ERROR_NOTE}
        if high:
            result.notes.append(
                "recursive method: estimated error above 1 % at order(s) "
                + ", ".join(f"{k} ({100 * v:.1f} %)" for k, v in high.items())
                + f" at {s['cell_m']:g} m cells (worst receiver; from a run at "
                f"{ESTIMATE_COARSEN * s['cell_m']:g} m): use a smaller --cell or Monte Carlo")
    if s["method"] == "montecarlo" and K_ >= 1:
        note = no_hit_note(result)
        if note:
            result.notes.append(note)
    result.seconds = time.perf_counter() - t0
    if s["method"] == "montecarlo" and K_ >= 1:
        busy = sum(lk.kernel_seconds for lk in links)
        result.ray_bounces_per_s = len(links) * ctx.rays * K_ / busy if busy > 0 else None
    return result


def _error_estimate(scene, s, fine: RoomResult, threads) -> dict:
    """Per link, the estimated relative error of each order: ``|H(h) - H(2h)| / 3 / H(h)``
    (Richardson for a method of order h^2) from the same run at twice the cell size; with
    glossy materials plus ``|H'(2h) - H(2h)| / H(h)``, ``H'`` with a quarter of the lobe rays.

    The lobe rays are a fixed angular quadrature of each glossy cell's first reflection:
    their error does not shrink with the cell size and is not smooth in it (aliasing with
    the grid), so cell halving alone cannot see it. Seen (audit t12: Phong and glossy
    walls, receiver 1 m from the Phong wall, 0.125 m cells, 4M-ray Monte Carlo with
    relative stderr 0.08-0.13 %): orders 2 and 3 were -0.25 % and +0.66 % off while the
    cell-halving estimate said 0.02 %; the lobe term brings it to 0.5-2 %."""
    coarse_cell = ESTIMATE_COARSEN * s["cell_m"]
    if coarse_cell > float(min(scene.size)):
        return {key: np.full(fine.bounces + 1, np.nan) for key in fine.links}
    kw = dict(method="recursive", bounces=fine.bounces, cell_m=coarse_cell,
              time_resolution_ns=s["time_resolution_ns"], threads=threads, estimate_error=False)
    coarse = simulate(scene, **kw)
    glossy = any(not m.is_lambertian for m in scene.materials.values())
    fewer = simulate(scene, lobe_rays=max(R.LOBE_RAYS // 4, 16), **kw) if glossy else None
    out = {}
    for key, lk in fine.links.items():
        a = lk.power_w
        b = coarse.links[key].power_w
        lobe = 0.0 if fewer is None else np.abs(fewer.links[key].power_w - b)
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.where(a > 0, (np.abs(a - b) / 3.0 + lobe) / a, 0.0)
        err[0] = 0.0
        out[key] = err
    return out


def worst_error_estimate(result: RoomResult) -> np.ndarray | None:
    """Per order (index 0: the line of sight, 0), the largest estimated relative error over
    the links, leaving out a link's order that carries less than :data:`NEGLIGIBLE_SHARE`
    of the link's power, and estimates that could not be made (NaN); None without one."""
    if not result.error_estimate:
        return None
    worst = np.zeros(result.bounces + 1)
    for key, err in result.error_estimate.items():
        power = result.links[key].power_w
        counted = np.isfinite(err) & (power >= NEGLIGIBLE_SHARE * power.sum())
        worst = np.maximum(worst, np.where(counted, err, 0.0))
    return worst


def no_hit_note(result: RoomResult) -> str | None:
    """The Monte Carlo links and orders that no ray reached (power 0, standard error NaN:
    zero hits say the power is below what ``rays`` rays can resolve, not that it is 0),
    as one printed note; None when every order of every link got a hit."""
    missed = {}
    for (e, r), lk in sorted(result.links.items()):
        ks = [k for k in range(1, len(lk.power_w)) if np.isnan(lk.stderr_w[k])]
        if ks:
            missed[f"{result.scene.emitters[e].name} -> {result.scene.receivers[r].name}"] = ks
    if not missed:
        return None
    shown = "; ".join(f"{name} order(s) {', '.join(map(str, ks))}"
                      for name, ks in list(missed.items())[:5])
    more = f" and {len(missed) - 5} more link(s)" if len(missed) > 5 else ""
    return (f"Monte Carlo: no ray reached {shown}{more} ({result.rays} rays per link): their "
            "power reads 0 with standard error NaN (unknown, not exactly 0; a narrow field of "
            "view or a receiver close to a wall sees few hit points): use more --rays or the "
            "recursive method")


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
        if ctx.method == "recursive" and ctx.threads > 1 and len(tasks) > 1:
            # receivers' gathers are independent: threads (the kernels release the GIL)
            with cf.ThreadPoolExecutor(max_workers=ctx.threads) as pool:
                for res in pool.map(lambda t: _run_task(ctx, t), tasks):
                    out.extend(res)
                    tick(len(res))
            return out
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


def _trace_inputs(ctx, em, rx):
    room_mat, box_mat = face_material_indices(ctx.scene)
    scene = K.TraceScene(np.asarray(ctx.scene.size, float), ctx.boxes, room_mat, box_mat)
    link = K.TraceLink(np.asarray(em.position, float), np.asarray(em.direction, float),
                       (float(em.order), float(em.power_w)), np.asarray(rx.position, float),
                       np.asarray(rx.direction, float),
                       (float(rx.gain_area), float(np.cos(np.radians(rx.fov_deg)))))
    return scene, link


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
    kernel_s = 0.0
    if Kb >= 1:
        out = K.TraceOut(np.zeros((Kb, ctx.n_bins)), np.zeros((Kb, 3)), np.zeros((Kb, 2)),
                         np.zeros(Kb), reflected, np.zeros(Kb + K.TERMS_MAX))
        tscene, tlink = _trace_inputs(ctx, em, rx)
        _warm_tracer(ctx, tscene, tlink, Kb)
        t0 = time.perf_counter()
        K.trace_rays(link_seed(ctx.seed, e, r), ctx.rays, tscene, tlink, ctx.mats,
                     (ctx.dt, 2 * np.pi * em.modulation_hz), out)
        kernel_s = time.perf_counter() - t0
        hist[1:] = out.hist
        power[1:], m1[1:], m2[1:] = out.mom[:, 0], out.mom[:, 1], out.mom[:, 2]
        phasor[1:] = out.ph[:, 0] + 1j * out.ph[:, 1]
        stderr[1:] = np.sqrt(np.maximum(out.sumsq - out.mom[:, 0] ** 2 / ctx.rays, 0.0))
        # no ray reached the receiver at an order: 0 +- 0 would claim certainty
        stderr[1:][out.mom[:, 0] <= 0.0] = np.nan
    link = LinkResult(e, r, power, m1, m2, phasor, stderr, hist.astype(np.float32), reflected,
                      tau_los)
    link.kernel_seconds = kernel_s
    return link


_TRACER_READY = False


def _warm_tracer(ctx, tscene, tlink, Kb):
    """Load the compiled tracer once per process (so that ray rates exclude it)."""
    global _TRACER_READY
    if _TRACER_READY:
        return
    out = K.TraceOut(np.zeros((Kb, 4)), np.zeros((Kb, 3)), np.zeros((Kb, 2)), np.zeros(Kb),
                     np.zeros(Kb), np.zeros(Kb + K.TERMS_MAX))
    K.trace_rays(0, 1, tscene, tlink, ctx.mats, (ctx.dt, 0.0), out)
    _TRACER_READY = True


# ----------------------------------------------------------------------------- recursive
def _recursive_link(ctx: _Context, e: int, r: int) -> LinkResult:
    scene = ctx.scene
    Kb = ctx.bounces
    T_ = ctx.n_bins
    hist = np.zeros((Kb + 1, T_))
    power, m1, m2 = np.zeros(Kb + 1), np.zeros(Kb + 1), np.zeros(Kb + 1)
    phasor = np.zeros(Kb + 1, complex)
    reflected = np.full(Kb, np.nan)
    tau_los = _los(ctx, e, r, hist, power, m1, m2, phasor)
    if Kb >= 1:
        st = ctx.emitter_states[e]
        p, a1, a2, ph, h = R.receiver_link(ctx.geo, st, scene.receivers[r], T_)
        power[1:], m1[1:], m2[1:], phasor[1:], hist[1:] = p, a1, a2, ph, h
        reflected = st.reflected.copy()
    return LinkResult(e, r, power, m1, m2, phasor, np.zeros(Kb + 1), hist.astype(np.float32),
                      reflected, tau_los)


__all__ = ["simulate", "RoomResult", "LinkResult", "link_seed", "worst_error_estimate", "DEFAULTS"]
