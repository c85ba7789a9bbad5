"""The contract of every registered selector (:data:`irreflect.selection.SELECTORS`): a
selector added with one registry line is checked here without edits.

Each must spend at most the budget, return a non-dominated frontier that ends close to the
all-points fit, choose only allowed points, give the same result for the same seed, and
refuse options it does not honour (a checkpoint, initial masks) instead of ignoring them.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import synthetic

from irreflect.errors import IrreflectError
from irreflect.selection import SELECTORS, run_selection

BUDGET = dict(pop_size=20, generations=10, max_points=16)


@pytest.fixture(scope="module")
def noisy():
    return synthetic(noise=0.004, seed=3, name="noisy")


@pytest.fixture(scope="module", params=sorted(SELECTORS))
def outcome(request, noisy):
    allowed = np.abs(noisy.theta_deg) <= 60
    res = run_selection(noisy, selector=request.param, seed=0, candidates=allowed, **BUDGET)
    return request.param, allowed, res


def test_front_is_valid_and_within_budget(outcome):
    selector, allowed, res = outcome
    f = res.front["one_minus_r2"].to_numpy()
    n = res.front["n_points"].to_numpy()
    assert res.selector == selector
    assert np.all(np.diff(n) > 0) and np.all(np.diff(f) < 0), selector  # non-dominated
    assert 0 < res.evaluations <= BUDGET["pop_size"] * BUDGET["generations"]
    assert n.max() <= BUDGET["max_points"]
    assert res.front["r2"].max() > 0.95, selector
    for mask in res.masks.values():
        assert not (mask & ~allowed).any(), f"{selector} chose a point outside the candidates"


def test_same_seed_same_front(outcome, noisy):
    selector, allowed, res = outcome
    again = run_selection(noisy, selector=selector, seed=0, candidates=allowed, **BUDGET)
    assert again.front[["n_points", "r2"]].equals(res.front[["n_points", "r2"]])


@pytest.mark.parametrize("selector", sorted(SELECTORS))
def test_options_a_selector_does_not_honour_are_refused(selector, noisy, tmp_path):
    spec = SELECTORS[selector]
    masks = np.zeros((1, noisy.n_points), bool)
    masks[0, :10] = True
    small = dict(pop_size=4, generations=1, max_points=10)
    if not spec.resumable:
        with pytest.raises(IrreflectError, match="checkpoint"):
            run_selection(noisy, selector=selector, checkpoint=tmp_path / "c.ckpt", **small)
        assert not (tmp_path / "c.ckpt").exists()
    if not spec.takes_initial:
        with pytest.raises(IrreflectError, match="initial"):
            run_selection(noisy, selector=selector, initial=masks, **small)
    if spec.resumable and spec.takes_initial:
        res = run_selection(noisy, selector=selector, checkpoint=tmp_path / "c.ckpt",
                            initial=masks, **small)
        assert (tmp_path / "c.ckpt").exists() and len(res.front) > 0
