"""Physics against analytical solutions (docs/physics.md)."""
import numpy as np
import pytest

from tfm import Params, RunWarning, simulate, theory


@pytest.fixture(scope="module")
def hertz_run():
    # F_th = 0: no tension anywhere, so loading is frictionless non-adhesive Hertz contact
    p = Params.from_dict(dict(spacing="1/128", f_th=0.0, shape="paraboloid", radius=1.0,
                              max_indent=0.02, step=1e-3))
    return p, simulate(p)


def test_hertz_force_and_radius(hertz_run):
    p, res = hertz_run
    load = res.curve[res.curve["phase"] == "load"]
    row = load.iloc[-1]
    assert row["indent"] == pytest.approx(0.02)
    # the bar: force within 0.5% (discretization error at a/spacing ~ 18)
    P_hertz = theory.hertz_force(0.02, 1.0)
    assert abs(row["force"] / P_hertz - 1) < 5e-3
    # contact radius within one spacing (the contact edge is resolved to one spring)
    assert abs(row["contact_radius"] - theory.hertz_radius(0.02, 1.0)) < p.spacing


def test_hertz_unloading_retraces_loading(hertz_run):
    """With F_th = 0 there is no hysteresis: the unloading force equals the loading one."""
    _, res = hertz_run
    c = res.curve
    load = c[c.phase == "load"].set_index("indent")["force"]
    unload = c[c.phase == "unload"].set_index("indent")["force"]
    common = load.index.intersection(unload.index)
    assert len(common) > 10
    # a spring at the contact edge may leave one step later: allow 1% of the peak force
    assert np.allclose(load[common], unload[common], rtol=0, atol=1e-2 * load.max())
    assert res.summary["pull_off_force"] < 1e-3 * load.max()


def test_a_contact_that_never_pulls_has_no_pull_off(hertz_run):
    """Without tension at any step there is no pull-off: its force is +0.0 (it was -0.0),
    its indent and radius NaN (they were those of an arbitrary step at P = 0), and the
    figure draws no snap-off jump."""
    from tfm.plots import split_snap_off

    _, res = hertz_run
    s, c = res.summary, res.curve
    assert (-c["force"]).max() <= 0.0
    assert s["pull_off_force"] == 0.0 and not np.signbit(s["pull_off_force"])
    assert np.isnan(s["pull_off_indent"]) and np.isnan(s["pull_off_contact_radius"])
    assert split_snap_off(c[c["phase"] == "unload"])[1] is None


def test_sphere_approaches_paraboloid_at_small_indentation():
    kw = dict(spacing="1/64", f_th=0.0, radius=1.0, max_indent=0.01, step=1e-3)
    sph = simulate(Params.from_dict(dict(kw, shape="sphere"))).curve
    par = simulate(Params.from_dict(dict(kw, shape="paraboloid"))).curve
    # x0 differs by r^4/(8R^3) ~ 1e-6 relative here; forces agree to 1%
    i = sph.index[sph.phase == "load"][-1]
    assert sph.loc[i, "force"] == pytest.approx(par.loc[i, "force"], rel=1e-2)


@pytest.fixture(scope="module")
def adhesive_run():
    p = Params.from_dict(dict(spacing="1/64", alpha=0.75, k_th=0.02, shape="paraboloid",
                              max_indent=0.05, step=5e-4))
    return simulate(p)


def test_adhesive_hysteresis(adhesive_run):
    c = adhesive_run.curve
    load = c[c.phase == "load"].set_index("indent")["force"]
    unload = c[c.phase == "unload"].set_index("indent")["force"]
    common = load.index.intersection(unload.index)
    common = common[common < 0.0495]
    # unloading lies below loading at every indentation both branches visit
    assert (unload[common] < load[common]).all()
    assert adhesive_run.summary["pull_off_force"] > 0
    assert adhesive_run.summary["pull_off_indent"] < 0.05


def test_area_constant_until_first_snap(adhesive_run):
    c = adhesive_run.curve
    unload = c[c.phase == "unload"]
    first = np.flatnonzero(unload["n_snapped"].to_numpy() > 0)[0]
    before = unload.iloc[:first]
    assert len(before) > 10
    assert (before["n_contact"] == c[c.phase == "load"]["n_contact"].iloc[-1]).all()
    # and the force turns tensile before any spring snaps
    assert before["force"].min() < 0


def test_pull_off_is_near_jkr(adhesive_run):
    """At alpha = 0.75, K_th plays K_IC: F_max ~ (3 pi^2/4) k_th^2 R. At spacing 1/64 the
    discrete crack tip adds ~20% (the paper's own 7.6 vs 7.40 at 1/256 is +3%), so 30%."""
    jkr = theory.jkr_pull_off(0.02, 1.0)
    assert adhesive_run.summary["pull_off_force"] == pytest.approx(jkr, rel=0.3)


def test_edge_contact_is_reported():
    p = Params.from_dict(dict(spacing="1/32", f_th=0.0, shape="paraboloid", max_indent=0.05,
                              step=5e-3, extent=0.15))
    with pytest.warns(RunWarning, match="grid edge"):
        res = simulate(p)
    assert res.summary["contact_reached_edge"]
    assert "grid edge" in res.summary["warnings"]


def test_solver_non_convergence_is_reported():
    p = Params.from_dict(dict(spacing="1/32", f_th=0.0, shape="paraboloid", max_indent=0.02,
                              step=5e-3, max_iter=1, tol=1e-12, preconditioner="none",
                              allow="step"))  # 4 steps: enough to see the flag
    with pytest.warns(RunWarning, match="did not converge"):
        res = simulate(p)
    assert res.summary["solver_not_converged"]


@pytest.mark.parametrize("layout", [dict(), dict(layout="hexagonal"), dict(layout="jittered", jitter=0.3)],
                         ids=["square", "hexagonal", "jittered"])
def test_winkler_pull_off_exact_discrete_and_continuum_limit(layout):
    """Local kernel at alpha = 1. The springs are independent, so the exact discrete answer
    is a sum over springs: those in contact at the preload that have not yet reached
    sigma_th. The continuum limit is pi c_w k_th^2 R (docs/physics.md). On every layout: a
    hexagonal one was refused, as if the diagonal needed the FFT's square grid."""
    p = Params.from_dict(dict(spacing="1/64", kernel="local", c_w=1.0, alpha=1.0, k_th=0.05,
                              shape="paraboloid", max_indent="auto", step=1e-4, **layout))
    res = simulate(p)
    from tfm.geometry import heights, make_layout
    lay = make_layout(p)
    x0, A = heights(p, lay), lay.area
    stress_th = p.k_th                            # F_th = k_th A (alpha = 1): one stress for every spring
    loaded = x0 > -p.delta_max                      # in contact at the deepest point
    unload = res.curve[res.curve.phase == "unload"]
    exact = []
    for d in unload["d"]:
        sigma = (d - x0) / p.c_w                      # tension per unit area if still held
        # a spring leaves for good once its stress passes the threshold (it only grows)
        held = loaded & (sigma <= stress_th)
        exact.append((sigma[held] * A[held]).sum())
    exact = np.max(exact)
    # identical arithmetic up to the solver's tolerance
    assert res.summary["pull_off_force"] == pytest.approx(exact, rel=1e-8)
    # continuum: measured +2.5% at 1/64, from the ~125 partially-counted springs on the
    # rim of a 20-spacing disk; 5% bounds that lattice error with margin
    limit = theory.winkler_pull_off(1.0, 0.05, 1.0)
    assert res.summary["pull_off_force"] == pytest.approx(limit, rel=0.05)
