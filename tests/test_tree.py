"""The Barnes-Hut tree operator against its slow twin, the direct sum (issue 5).

The accuracy bound under test (tfm/kernels/tree.py): with q = min(theta/sqrt 2, 0.75)
and expansion order p, at every target

    |u_tree - u_direct| <= eps(theta) * sum_{s != t} |f_s| / r_ts,
    eps(theta) = q^(p+1) (1 + q) / (1 - q),

which tightens as theta shrinks. It is a rigorous (Legendre) bound, so it is asserted
pointwise, with only round-off on top.
"""
import numba
import numpy as np
import pytest

from tfm import Params, simulate, theory
from tfm.geometry import hexagonal_grid, jittered_grid, square_grid
from tfm.kernels.direct import BOUSSINESQ, LOCAL, NEIGHBORS, direct_sum
from tfm.kernels.tree import MORTON_BITS, build_nodes, morton_keys, subset_order
from tfm.operators import KernelSpec
from tfm.tree_operator import TreeOperator, tree_error_bound

THETAS = (0.3, 0.5, 0.7, 1.0)
# round-off of a sum of ~2000 terms of size |f|/r, relative to sum |f|/r: far below 1e-12
ROUNDOFF = 1e-12


@pytest.fixture(scope="module")
def jittered():
    # ~2000 springs with random offsets: no symmetry for the tree to profit from
    lay = jittered_grid(1.0 / 22, 1.0, 0.4, seed=3)
    rng = np.random.default_rng(7)
    src = np.sort(rng.choice(lay.n, size=lay.n * 2 // 3, replace=False)).astype(np.int64)
    tgt = rng.permutation(lay.n).astype(np.int64)            # unsorted targets on purpose
    f = rng.uniform(-1.0, 1.0, src.size) + 0.3               # mixed sign, nonzero mean
    spec = KernelSpec(BOUSSINESQ, np.inf, 3.8 / np.sqrt(lay.area))
    ref = direct_sum(lay.x, lay.y, spec.diag, src, f, tgt, BOUSSINESQ, np.inf)
    # the bound's scale: the off-diagonal sum of |f| / r at each target
    absu = direct_sum(lay.x, lay.y, np.zeros(lay.n), src, np.abs(f), tgt, BOUSSINESQ, np.inf)
    return lay, spec, src, tgt, f, ref, absu


def test_morton_subset_order_is_a_sort():
    rng = np.random.default_rng(0)
    x, y = rng.random(500), rng.random(500)
    keys = morton_keys(x, y, 0.0, 0.0, 1.0, MORTON_BITS)
    order = np.argsort(keys, kind="stable").astype(np.int64)
    sub = rng.choice(500, 200, replace=False).astype(np.int64)
    perm = subset_order(order, sub, 500)
    assert np.array_equal(np.sort(perm), np.arange(200))
    assert np.all(np.diff(keys[sub[perm]]) >= 0)


def test_tree_nodes_partition_the_points():
    rng = np.random.default_rng(1)
    keys = np.sort(morton_keys(rng.random(3000), rng.random(3000), 0.0, 0.0, 1.0, MORTON_BITS))
    start, end, skip, parent, leaf = build_nodes(keys, 16, MORTON_BITS)
    # leaves cover every point once, in order
    ls, le = start[leaf], end[leaf]
    assert ls[0] == 0 and le[-1] == 3000 and np.array_equal(ls[1:], le[:-1])
    assert np.all(le - ls <= 16)
    for k in np.flatnonzero(~leaf):
        # threaded layout: children are k+1, skip[k+1], ... up to skip[k]; >= 2 of them,
        # and their ranges tile the parent's
        kids = []
        c = k + 1
        while c < skip[k]:
            kids.append(c)
            c = skip[c]
        assert len(kids) >= 2 and c == skip[k]
        assert start[kids[0]] == start[k] and end[kids[-1]] == end[k]
        assert all(end[a] == start[b] for a, b in zip(kids[:-1], kids[1:]))
        assert np.all(parent[kids] == k)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_tree_within_stated_bound_of_direct(jittered, order):
    lay, spec, src, tgt, f, ref, absu = jittered
    rms = []
    for theta in THETAS:
        u = TreeOperator(spec, lay, theta=theta, order=order).apply(src, f, tgt)
        err = np.abs(u - ref)
        bound = tree_error_bound(theta, order)
        assert np.all(err <= bound * absu + ROUNDOFF * (absu + np.abs(ref))), (order, theta)
        rms.append(np.sqrt(np.mean(err ** 2)))
    # the bound tightens as theta shrinks, and so does the measured error
    bounds = [tree_error_bound(t, order) for t in THETAS]
    assert np.all(np.diff(bounds) > 0)
    assert np.all(np.diff(rms) > 0), rms


def test_tiny_theta_is_the_direct_sum(jittered):
    """theta -> 0 opens every node: only the exact near field and the self term remain."""
    lay, spec, src, tgt, f, ref, absu = jittered
    u = TreeOperator(spec, lay, theta=1e-6).apply(src, f, tgt)
    # same terms in a different order: round-off only
    np.testing.assert_allclose(u, ref, rtol=1e-12, atol=ROUNDOFF * absu.max())


def test_all_targets_and_cached_rebuilds(jittered):
    """tgt=None means every spring; the cached trees give the same numbers as fresh ones
    when the source set changes back and forth and the forces change."""
    lay, spec, src, tgt, f, ref, absu = jittered
    op = TreeOperator(spec, lay, theta=0.5)
    all_idx = np.arange(lay.n)
    u_all = op.apply(src, f)
    u_sub = op.apply(src, f, tgt)
    # tgt is a permutation of all springs: the same target groups, so the same bits
    assert np.array_equal(u_all[tgt], u_sub)
    other = src[::2]
    u_other = op.apply(other, f[::2], all_idx)
    fresh = TreeOperator(spec, lay, theta=0.5)
    assert np.array_equal(u_other, fresh.apply(other, f[::2], all_idx))
    assert np.array_equal(op.apply(src, 2.0 * f, tgt), 2.0 * u_sub)
    assert op.apply(src[:0], f[:0], tgt).tolist() == [0.0] * tgt.size
    assert op.apply(src, f, tgt[:0]).size == 0


def test_same_bits_for_any_thread_count(jittered):
    lay, spec, src, tgt, f, ref, absu = jittered
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one thread only")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        u1 = TreeOperator(spec, lay, theta=0.7).apply(src, f)
        numba.set_num_threads(min(4, numba.config.NUMBA_NUM_THREADS))
        u2 = TreeOperator(spec, lay, theta=0.7).apply(src, f)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(u1, u2)


def test_duplicate_sources_refused(jittered):
    lay, spec, *_ = jittered
    with pytest.raises(ValueError, match="distinct"):
        TreeOperator(spec, lay).apply(np.array([3, 3]), np.ones(2))


@pytest.mark.parametrize("kind", [LOCAL, NEIGHBORS])
def test_local_and_neighbors_use_exact_lists(kind):
    """No tree for short-ranged kernels: the operator must equal the direct sum to round-off."""
    lay = square_grid(1.0 / 16, 1.0) if kind == NEIGHBORS else hexagonal_grid(1.0 / 16, 1.0)
    cutoff = 2.0 / 16 if kind == NEIGHBORS else 0.0
    spec = KernelSpec(kind, cutoff, np.linspace(1.0, 2.0, lay.n))
    rng = np.random.default_rng(5)
    src = np.sort(rng.choice(lay.n, lay.n // 2, replace=False)).astype(np.int64)
    f = rng.normal(size=src.size)
    tgt = rng.permutation(lay.n)[:300].astype(np.int64)
    ref = direct_sum(lay.x, lay.y, spec.diag, src, f, tgt, kind, cutoff)
    u = TreeOperator(spec, lay, theta=0.5).apply(src, f, tgt)
    np.testing.assert_allclose(u, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())


# ------------------------------------------------------------------ full runs
def test_pull_off_matches_fft_on_the_square_grid():
    """The issue's bar: a full adhesive load-unload at spacing 1/64 with the tree gives
    the FFT's pull-off force within 0.5%."""
    kw = dict(spacing="1/64", alpha=0.75, k_th=0.02, shape="paraboloid", max_indent=0.05,
              step=5e-4)
    fft = simulate(Params.from_dict(dict(kw, operator="fft"))).summary["pull_off_force"]
    tree = simulate(Params.from_dict(dict(kw, operator="tree", theta=0.5))).summary
    assert not tree["warnings"]
    assert tree["pull_off_force"] == pytest.approx(fft, rel=5e-3)


@pytest.mark.parametrize("layout", ["hexagonal", "jittered"])
def test_hertz_loading_on_irregular_layouts(layout):
    """F_th = 0: the loading branch is Hertz. 1%: the discretization error at
    a / spacing ~ 9 (the square grid at 1/128 meets 0.5%), far above the tree's error."""
    p = Params.from_dict(dict(spacing="1/64", f_th=0.0, shape="paraboloid", radius=1.0,
                              max_indent=0.02, step=2e-3, operator="tree", layout=layout))
    res = simulate(p)
    load = res.curve[res.curve["phase"] == "load"]
    row = load.iloc[-1]
    assert row["indent"] == pytest.approx(0.02)
    assert row["force"] == pytest.approx(theory.hertz_force(0.02, 1.0), rel=1e-2)
