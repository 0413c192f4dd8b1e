"""The contact solve and Algorithm 1 against slow dense references."""
import numpy as np
import pytest

from naive import algorithm1_dense, compliance_double_loop
from tfm import Params, simulate
from tfm.geometry import heights, make_layout
from tfm.operators import kernel_spec
from tfm.kernels.contact import solve_on_set
from tfm.operators import pre_data
from tfm.simulate import build_problem
from tfm.tree_operator import tree_error_bound


@pytest.mark.parametrize("operator", ["fft", "direct", "tree"])
def test_contact_solve_matches_dense_solve(operator):
    """The compiled PCG (solve_on_set) with each operator's data against np.linalg.solve
    on the dense C_SS of a disc, and its field C x against the dense product."""
    kw = dict(theta=0.3) if operator == "tree" else {}
    p = Params.from_dict(dict(spacing="1/16", k_th=0.05, operator=operator, **kw))
    prob, layout = build_problem(p)
    op, pre = prob.operator.compiled(), prob.precond.compiled()
    C = compliance_double_loop(layout.x, layout.y, kernel_spec(p, layout).diag, p.kernel, np.inf)
    idx = np.flatnonzero(np.hypot(layout.x, layout.y) < 0.3)
    b = 0.01 - prob.x0[idx]
    x, u = np.zeros(idx.size), np.zeros(layout.n)
    it, conv, res = solve_on_set(op, pre, idx, b, x, b, False, 1e-12, 500, u, True)
    assert conv and it > 0 and res <= 1e-12
    ref = np.linalg.solve(C[np.ix_(idx, idx)], b)
    # residual 1e-12 relative, condition ~10^2: 1e-9 of the largest force leaves margin.
    # The tree's sums are exact to its bound, tree_error_bound(0.3) = 6.6e-4 of sum |f|/r
    # (all forces of one sign here, so of u itself); measured: 1e-7 (x) and 2e-6 (u).
    tol = tree_error_bound(0.3) if operator == "tree" else 1e-9
    assert np.allclose(x, ref, rtol=0, atol=tol * np.abs(ref).max())
    assert np.allclose(u, C[:, idx] @ x, rtol=0, atol=tol * np.abs(u).max())


def test_contact_solve_reports_non_convergence():
    p = Params.from_dict(dict(spacing="1/24", k_th=0.05, preconditioner="none"))
    prob, layout = build_problem(p)
    idx = np.flatnonzero(np.hypot(layout.x, layout.y) < 0.3)
    b = 0.01 - prob.x0[idx]
    it, conv, res = solve_on_set(prob.operator.compiled(), pre_data(), idx, b, np.zeros(idx.size), b,
                                 False, 1e-14, 3, np.zeros(0), False)
    assert not conv and it == 3 and res > 1e-14


_SUMMED = [(dict(kernel="boussinesq", k_th=0.05), "boussinesq"), (dict(kernel="boussinesq", f_th=0.0), "hertz"),
           (dict(kernel="neighbors", neighbor_rings=3, k_th=0.05), "neighbors")]


@pytest.mark.parametrize("kw, operator", [(kw, op) for kw, _ in _SUMMED for op in ("fft", "direct", "tree")]
                         + [(dict(kernel="local", k_th=0.05, alpha=1.0), None)],
                         ids=[f"{op}-{name}" for _, name in _SUMMED for op in ("fft", "direct", "tree")]
                         + ["local"])
def test_algorithm1_matches_dense_reference(kw, operator):
    """Whole load-unload curve at spacing 1/12 against np.linalg.solve on the dense C, with
    every operator feeding the one compiled loop (the local kernel, a diagonal, takes none)."""
    base = dict(spacing="1/12", radius=1.0, shape="paraboloid", max_indent=0.04, step=2e-3, tol=1e-12)
    if operator is not None:
        base["operator"] = operator
    base.update(kw)
    if operator == "tree" and base["kernel"] == "boussinesq":   # theta applies there only
        base["theta"] = 0.3
    p = Params.from_dict(base)
    res = simulate(p)
    layout = make_layout(p)
    spec = kernel_spec(p, layout)
    C = compliance_double_loop(layout.x, layout.y, spec.diag, p.kernel, spec.cutoff)
    f_th = p.k_th * layout.area ** p.alpha if p.k_th is not None else np.full(layout.n, p.f_th)
    ref = algorithm1_dense(C, heights(p, layout), f_th, res.curve["d"].to_numpy())
    assert np.array_equal(res.curve["n_contact"].to_numpy(), ref[:, 2])
    # forces: solve tolerance 1e-12 relative on well-conditioned (N < 400) systems; the
    # tree's 1/r sums are approximate, within tree_error_bound(0.3) = 6.6e-4 (relative)
    exact = operator != "tree" or p.kernel != "boussinesq"
    rel = 1e-9 if exact else tree_error_bound(0.3)
    assert np.allclose(res.curve["force"], ref[:, 1], rtol=0, atol=rel * np.abs(ref[:, 1]).max())
    assert res.summary["unload_complete"] and not res.summary["warnings"]


def test_single_snap_rule_is_recorded_and_differs_only_in_rounds():
    p = Params.from_dict(dict(spacing="1/16", k_th=0.05, shape="paraboloid", max_indent=0.04,
                              step=2e-3, snap_rule="single"))
    res = simulate(p)
    assert "single" in p.canonical_json()
    # one change per round: rounds >= changes + 1 on every step
    c = res.curve
    assert (c["rounds"] >= c["n_snapped"] + c["n_entered"] + 1).all()
    assert res.summary["pull_off_force"] > 0
