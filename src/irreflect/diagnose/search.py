"""Fitting sets of extensions on top of a base model, each started where it should be.

A set of effects is one model, ``extend(base, canonical_order(set))``: the order in which
extensions wrap each other is physical, not the order they were found in. The specular
lobe's tilt is innermost (it moves that lobe only), then the extra lobes (retroreflection,
halo; about directions the tilt does not move), then the reflectance that depends on the
angle of incidence (it scales every lobe), then an additive background (stray light is not
scaled by the surface), then the receiver arm's zero error (it moves everything the
detector sees), and outermost a gain drift between angles of incidence (it scales
everything the detector reads; it commutes with the zero error, which moves theta only).
Extensions registered by users come after the catalogue's, before the angle offset.

Starts of a set ``U`` (:func:`starts_for`): the optimum of every fitted subset of ``U``
one smaller, with the missing extension at its neutral value (the nested model's optimum
is a point of ``U``), plus a scan: along the missing extension's own coordinates, over
their whole range on a fine grid, the other coordinates held at that optimum and the
linear coefficients solved for, the best few local minima. A lobe a thousand times higher
than the diffuse floor and one degree wide moves off its receiver for a shift of one
degree: the cost along a shift is a comb of narrow dips, which a scan finds and a local
search from a neutral start does not. A gain drift (one coordinate per angle of incidence,
too many to scan) starts instead from the factors that rescale each angle's curve of the
fitted subset onto its readings (:func:`irreflect.diagnose.gain.gain_starts`).
"""

from __future__ import annotations

import numpy as np

from ..errors import IrreflectError
from ..models.base import Geometry, ReflectionModel
from ..models.extensions import GAIN_DRIFT, Extension, get_extension

#: the physical nesting of the catalogue (innermost first); see the module docstring
CANONICAL = ("offspecular_peak", "retroreflection", "specular_halo", "incidence_reflectance",
             "background")
OUTERMOST = ("angle_offset", GAIN_DRIFT)
#: scan points per coordinate (one coordinate; two coordinates: this many per axis)
SCAN_1D = 241
SCAN_2D = 25


def canonical_order(names) -> tuple[str, ...]:
    """The nesting order of a set of extension names (see the module docstring)."""
    names = list(dict.fromkeys(names))
    known = [n for n in CANONICAL if n in names]
    last = [n for n in OUTERMOST if n in names]
    other = [n for n in names if n not in CANONICAL and n not in OUTERMOST]
    return tuple(known + other + last)


def set_name(names) -> str:
    """``"a+b"`` in canonical order (``""`` for the empty set)."""
    return "+".join(canonical_order(names))


class ModelSets:
    """The models of sets of extensions on one base, with their coordinate blocks;
    ``local``: extensions of this table only (name -> extension, e.g. the gain drift of
    :func:`irreflect.models.extensions.gain_drift`), found before the registry's."""

    def __init__(self, base: ReflectionModel, local: dict | None = None):
        self.base = base
        self.local = dict(local or {})
        self._models: dict[tuple[str, ...], ReflectionModel] = {(): base}
        self._blocks: dict[str, tuple[int, np.ndarray]] = {}

    def extension(self, name: str):
        """The extension of that name: this table's own, else the registry's."""
        return self.local[name] if name in self.local else get_extension(name)

    def model(self, names) -> ReflectionModel:
        key = canonical_order(names)
        if key not in self._models:
            model = self.base
            for name in key:
                model = self.extension(name)(model)
                if not isinstance(model, ReflectionModel):
                    raise IrreflectError(f"extension '{name}' returned "
                                         f"{type(model).__name__}, expected a ReflectionModel")
            self._models[key] = model
        return self._models[key]

    def block(self, name: str, gamma=None, theta=None, power=None) -> tuple[int, np.ndarray]:
        """Size of an extension's nonlinear block and its neutral value."""
        if name not in self._blocks:
            ext = self.extension(name)
            if isinstance(ext, Extension):
                size = len(ext.nonlinear_names)
                neutral = (np.asarray(ext.z_starts[0], float) if size and ext.z_starts
                           else np.zeros(size))
            else:
                one = self.model([name])
                size = one.n_nonlinear - self.base.n_nonlinear
                neutral = np.zeros(size)
                if size and gamma is not None:
                    rows = np.atleast_2d(one.starts(gamma, theta, power))
                    neutral = rows[0, self.base.n_nonlinear:]
            self._blocks[name] = (size, neutral.reshape(size))
        return self._blocks[name]

    def embed(self, z, names, target) -> np.ndarray:
        """The coordinates ``z`` of the model of ``names`` as a point of the model of
        ``target`` (a superset): the extra extensions at their neutral values."""
        src, dst = canonical_order(names), canonical_order(target)
        pb = self.base.n_nonlinear
        z = np.asarray(z, float).ravel()
        parts, at = {}, pb
        for n in src:
            size, _ = self.block(n)
            parts[n] = z[at:at + size]
            at += size
        out = [z[:pb]]
        for n in dst:
            out.append(parts[n] if n in parts else self.block(n)[1])
        return np.concatenate(out)

    def restrict(self, z, names, target) -> np.ndarray:
        """The coordinates ``z`` of the model of ``names`` as a point of the model of
        ``target`` (a subset): the blocks of the extensions ``target`` lacks dropped."""
        keep = set(canonical_order(target))
        pb = self.base.n_nonlinear
        z = np.asarray(z, float).ravel()
        out, at = [z[:pb]], pb
        for n in canonical_order(names):
            size, _ = self.block(n)
            if n in keep:
                out.append(z[at:at + size])
            at += size
        return np.concatenate(out)

    def block_slice(self, name, names) -> slice:
        """Where ``name``'s block lies in the coordinates of the model of ``names``."""
        at = self.base.n_nonlinear
        for n in canonical_order(names):
            size, _ = self.block(n)
            if n == name:
                return slice(at, at + size)
            at += size
        raise KeyError(name)


def _projected_costs(model, geom, z_rows, y, w) -> np.ndarray:
    """Weighted least-squares cost of every row of ``z_rows`` with the linear coefficients
    solved for (unconstrained: a scan's ranking, not a fit)."""
    basis, _ = model.basis(geom, z_rows, False)  # (B, n, L)
    bw = basis * w[None, :, None]
    yw = y * w
    gram = np.einsum("bnl,bnm->blm", bw, bw)
    rhs = np.einsum("bnl,n->bl", bw, yw)
    ridge = 1e-12 * np.maximum(np.einsum("bll->b", gram), 1e-300)[:, None, None]
    eye = np.eye(gram.shape[-1])[None]
    with np.errstate(all="ignore"):
        try:
            coef = np.linalg.solve(gram + ridge * eye, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            coef = np.einsum("blm,bm->bl", np.linalg.pinv(gram), rhs)
        resid = yw[None] - np.einsum("bnl,bl->bn", bw, coef)
        cost = np.sum(resid * resid, axis=1)
    return np.where(np.isfinite(cost), cost, np.inf)


def scan_starts(sets: ModelSets, names, name, z_from, gamma, theta, power, weights,
                keep: int = 4) -> np.ndarray:
    """Scan the coordinates of extension ``name`` in the model of ``names`` (which holds
    it) over their whole range, the others at ``z_from`` (a point of that model); the
    ``keep`` best local minima as rows of starts (none when the extension has no
    nonlinear coordinate)."""
    model = sets.model(names)
    sl = sets.block_slice(name, names)
    size = sl.stop - sl.start
    if size == 0 or size > 2:
        return np.zeros((0, model.n_nonlinear))
    lo, hi = model.screen_box()
    lo, hi = np.maximum(model.z_lower[sl], lo[sl]), np.minimum(model.z_upper[sl], hi[sl])
    if size == 1:
        axes = [np.linspace(lo[0], hi[0], SCAN_1D)]
    else:
        axes = [np.linspace(lo[i], hi[i], SCAN_2D) for i in range(2)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, size)
    rows = np.repeat(np.asarray(z_from, float)[None], grid.shape[0], axis=0)
    rows[:, sl] = grid
    geom = Geometry.of(np.asarray(gamma, float)[None], np.asarray(theta, float)[None])
    cost = _projected_costs(model, geom, rows, np.asarray(power, float),
                            np.asarray(weights, float))
    shape = tuple(a.size for a in axes)
    c = cost.reshape(shape)
    # local minima of the grid (strictly lower than every neighbour along each axis)
    is_min = np.isfinite(c)
    for ax in range(c.ndim):
        lower = np.full(shape, np.inf)
        upper = np.full(shape, np.inf)
        idx = [slice(None)] * c.ndim
        src = [slice(None)] * c.ndim
        idx[ax], src[ax] = slice(1, None), slice(None, -1)
        lower[tuple(idx)] = c[tuple(src)]
        idx[ax], src[ax] = slice(None, -1), slice(1, None)
        upper[tuple(idx)] = c[tuple(src)]
        is_min &= (c <= lower) & (c <= upper)
    flat = np.nonzero(is_min.ravel())[0]
    flat = flat[np.argsort(cost[flat], kind="stable")][:keep]
    return rows[flat]


def starts_for(sets: ModelSets, names, fitted: dict, gamma, theta, power, weights) -> np.ndarray:
    """Starts of the model of ``names``: every fitted subset one smaller embedded in it,
    and for each a scan of the extension it lacks (``fitted``: set name -> z)."""
    target = canonical_order(names)
    rows = []
    for missing in target:
        sub = tuple(n for n in target if n != missing)
        key = set_name(sub)
        if key not in fitted:
            continue
        z0 = sets.embed(fitted[key], sub, target)
        rows.append(z0[None])
        rows.append(scan_starts(sets, target, missing, z0, gamma, theta, power, weights))
    model = sets.model(target)
    if not rows:
        return np.zeros((0, model.n_nonlinear))
    out = np.concatenate(rows, axis=0)
    out = np.clip(out, model.z_lower, model.z_upper)
    return np.unique(out, axis=0)

