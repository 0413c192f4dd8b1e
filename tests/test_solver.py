"""The contact solve and Algorithm 1 against slow dense references."""
import numpy as np
import pytest

from naive import algorithm1_dense, compliance_double_loop
from tfm import Params, simulate
from tfm.geometry import heights, make_layout
from tfm.operators import kernel_spec
from tfm.solver import pcg


def test_pcg_matches_dense_solve():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(60, 60))
    A = A @ A.T + 60 * np.eye(60)
    b = rng.normal(size=60)
    x, stats = pcg(lambda v: A @ v, b, np.zeros(60), lambda r: r / np.diag(A), 1e-12, 500)
    assert stats.converged
    # residual 1e-12 relative, condition number ~10: error well under 1e-10
    assert np.allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-10 * np.abs(x).max())


def test_pcg_reports_non_convergence():
    A = np.diag(np.linspace(1, 1e4, 200))
    x, stats = pcg(lambda v: A @ v, np.ones(200), np.zeros(200), None, 1e-14, 3)
    assert not stats.converged and stats.iters == 3 and stats.residual > 1e-14


@pytest.mark.parametrize("kw", [dict(kernel="boussinesq", k_th=0.05),
                                dict(kernel="boussinesq", f_th=0.0),
                                dict(kernel="neighbors", neighbor_rings=3, k_th=0.05),
                                dict(kernel="local", k_th=0.05, alpha=1.0)],
                         ids=["boussinesq", "hertz", "neighbors", "local"])
@pytest.mark.parametrize("operator", ["fft", "direct"])
def test_algorithm1_matches_dense_reference(kw, operator):
    """Whole load-unload curve at spacing 1/12 against np.linalg.solve on the dense C."""
    base = dict(spacing="1/12", radius=1.0, shape="paraboloid", max_indent=0.04, step=2e-3,
                operator=operator, tol=1e-12)
    base.update(kw)
    p = Params.from_dict(base)
    res = simulate(p)
    layout = make_layout(p)
    spec = kernel_spec(p, layout)
    C = compliance_double_loop(layout.x, layout.y, spec.diag, p.kernel, spec.cutoff)
    f_th = p.k_th * layout.area ** p.alpha if p.k_th is not None else np.full(layout.n, p.f_th)
    ref = algorithm1_dense(C, heights(p, layout), f_th, res.curve["d"].to_numpy())
    assert np.array_equal(res.curve["n_contact"].to_numpy(), ref[:, 2])
    # forces: solve tolerance 1e-12 relative on well-conditioned (N < 400) systems
    assert np.allclose(res.curve["force"], ref[:, 1], rtol=0, atol=1e-9 * np.abs(ref[:, 1]).max())
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
