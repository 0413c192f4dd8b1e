"""Force control (tfm.protocol.force_control) against displacement control.

The paper (Sec. 3.1): under force control "the entire contact would break and the force
drop to zero at the maximum tensile force". So the jump-off force is the displacement-
controlled F_max, and the contact at jump-off is the one at F_max."""
import numpy as np
import pytest

import tfm
from tfm.params import ParameterError, Params

STANDARD = dict(alpha=0.75, k_th=0.02, shape="paraboloid", radius=1.0, max_indent=0.05)


@pytest.mark.parametrize("spacing", [1 / 64, 1 / 128])
def test_jump_off_is_the_displacement_controlled_pull_off(spacing):
    disp = tfm.simulate(spacing=spacing, **STANDARD).summary
    res = tfm.simulate(spacing=spacing, control="force", **STANDARD)
    s = res.summary
    assert s["unload_complete"] and not s["warnings"]
    # Displacement control samples F(d) every `step` and misses the top of the last
    # linear stretch before a snap; force control finds it (bisection to load_step/1024).
    # 1 % is the bound; the measured gap is 0.7-0.8 %.
    assert s["jump_off_force"] == pytest.approx(disp["pull_off_force"], rel=0.01)
    assert s["jump_off_force"] >= disp["pull_off_force"]
    # the same contact: within 2 spacings (the bound; measured: equal)
    assert abs(s["jump_off_contact_radius"] - disp["pull_off_contact_radius"]) <= 2 * spacing
    last = res.curve.iloc[-1]
    assert last["n_contact"] == 0 and last["force"] == 0.0


def test_the_loop_closes_at_the_jump_off():
    """The row after the jump-off had the d at which the Newton steps found no spring left,
    an artefact 3x deeper than the jump at 1/64; the hysteresis ran a line to it (+36 %)
    and the figure drew the jump there. Now the row sits at the last load held, with
    P = +0.0 (it was -0.0, shown as "P = -0"), and the hysteresis is the work up to the jump."""
    from tfm.analysis import hysteresis

    c = tfm.simulate(Params(spacing=1 / 64, control="force", f_th=None, **STANDARD)).curve
    jump, after = c.iloc[-2], c.iloc[-1]
    assert after["n_contact"] == 0 and jump["n_contact"] > 0 and jump["force"] < 0
    assert after["d"] == jump["d"] and after["indent"] == jump["indent"]
    assert after["force"] == 0.0 and np.signbit(after["force"]) == False  # noqa: E712
    assert hysteresis(c) == hysteresis(c.iloc[:-1])     # the drop adds no area


def test_held_loads_are_the_targets():
    """Each held step carries its target load: the Newton step on a fixed contact set is exact."""
    p = Params(spacing=1 / 32, control="force", load_step=2e-4, **STANDARD, f_th=None)
    res = tfm.simulate(p)
    c = res.curve
    load = c[c["phase"] == "load"]
    targets = np.minimum(np.arange(1, len(load) + 1) * p.load_decrement, p.peak_load)
    # CG tolerance 1e-10 on the forces; the load is their sum
    np.testing.assert_allclose(load["force"], targets, rtol=1e-8, atol=1e-12)
    unload = c[(c["phase"] == "unload") & (c["n_contact"] > 0)]
    first = unload.iloc[: len(unload) // 2]          # before the bisection of the last step
    expected = p.peak_load - np.arange(1, len(first) + 1) * p.load_decrement
    np.testing.assert_allclose(first["force"], expected, rtol=1e-8, atol=1e-12)


def test_no_spring_in_contact_after_jump_off():
    from tfm import protocol
    from tfm.simulate import build_problem

    p = Params(spacing=1 / 32, control="force", **STANDARD, f_th=None)
    prob, _ = build_problem(p)
    seen = []
    protocol.run(p, prob, observe=lambda state, rec: seen.append((rec.n_contact, int(state.contact.sum()))))
    assert seen[-1] == (0, 0)
    assert all(n > 0 for n, _ in seen[:-1])


@pytest.mark.parametrize("values, message", [
    ({"max_load": 0.01}, "max_load: 0.01 has no effect here; it applies only when control='force'"),
    ({"load_step": 1e-4}, "load_step: 0.0001 has no effect here; it applies only when control='force'"),
    ({"control": "force", "max_load": -1}, "max_load: must be > 0"),
    ({"control": "force", "max_load": 0.01, "max_indent": 0.05}, "max_indent: under control='force'"),
    ({"control": "force", "shape": "flat_punch"}, "max_load: control='force' on a flat punch"),
    ({"control": "force", "max_load": 0.01, "load_step": 0.1}, "load_step: must be <= max_load"),
    ({"control": "forse"}, "control: unknown value 'forse'"),
    # a large or tiny max_load under displacement control was blamed on max_indent or
    # step, parameters the user had not set: its depth sized the preload even there
    ({"max_load": 1}, "max_load: 1.0 has no effect here; it applies only when control='force'"),
    ({"k_th": 0.02, "shape": "paraboloid", "max_load": 1e-9}, "max_load: 1e-09 has no effect here"),
    ({"control": "force", "max_load": 1}, "max_load: 1 would press a sphere of radius 1 in by 1.77"),
])
def test_protocol_parameters_fail_early(values, message):
    with pytest.raises(ParameterError, match=message):
        Params.from_dict(values)


@pytest.mark.parametrize("operator", ["fft", "direct"])
def test_unit_response_solves_are_counted_once_per_contact_set(operator):
    """Force control's extra solves (C_SS x = 1) appear in n_solves and solver_iters, and a
    second call on the same contact set reuses the solution."""
    from tfm.simulate import build_problem
    from tfm.solver import ContactState, CurveResult

    p = Params.from_dict(dict(STANDARD, spacing="1/32", operator=operator, max_indent=0.02, step=2e-3))
    prob, _ = build_problem(p)
    state, out = ContactState(prob), CurveResult()
    state.advance(-0.01, 0, "load", out)
    solves, iters = out.n_solves, out.solver_iters
    x = state.unit_response(out)
    assert out.n_solves == solves + 1 and out.solver_iters > iters
    assert np.all(x[state.contact] > 0) and np.all(x[~state.contact] == 0)
    again = state.unit_response(out)
    assert out.n_solves == solves + 1 and np.array_equal(x, again)


def test_a_flat_punch_under_force_control_is_sized_and_reported_as_a_flat_punch():
    """A flat punch's preload is Boussinesq's depth P / (2 E* R), not a sphere's Hertz depth
    (0.0446 instead of 0.0126 for this load), the summary's max_indent is the depth the
    peak load reached, and no preload note: a flat punch's pull-off does not depend on it.
    The discrete punch is stiffer at the edge: its measured depth lies within 3 % of the
    continuum's at this spacing (2.4 % measured)."""
    from tfm.guards import check
    from tfm.theory import E_STAR

    p = Params(spacing=1 / 32, k_th=0.02, f_th=None, shape="flat_punch", radius=0.25, control="force", max_load=2e-3,
               step=1e-4)
    assert p.delta_max == pytest.approx(2e-3 / (2 * E_STAR * 0.25), rel=1e-14)
    assert check(p) == []
    # nor under displacement control with an automatic preload (it said "capped ... too shallow")
    assert check(p.replace(control="displacement", max_load=None, max_indent="auto", step=1e-3)) == []
    res = tfm.simulate(p)
    s = res.summary
    assert s["max_indent"] == res.curve["indent"].max()
    assert s["max_indent"] == pytest.approx(p.delta_max, rel=0.03)
    assert not s["warnings"]


@pytest.mark.parametrize("spacing", [1 / 32, 1 / 64])
def test_the_loading_branch_is_displacement_controls(spacing):
    """The Newton step of a load step went past its load when springs entered (an
    overshoot), and the springs pulled in stayed, held in tension when the flat backed
    off: at 1/32 the first load steps had up to 85 % more indent than displacement
    control's loading branch at the same load (0.00419 against 0.00227), and the first
    approach of one `step` did the same with a coarse step. Now the indent at each held
    load is displacement control's at that load within one step: both move the flat by at
    most `step`, so they may resolve an entry one step apart, no more (measured: 0.02 and
    0.01 steps; before, 7.7 and 1.6)."""
    p = Params(spacing=spacing, f_th=None, **STANDARD)
    disp = tfm.simulate(p).curve
    force = tfm.simulate(p.replace(control="force")).curve
    dl, fl = disp[disp["phase"] == "load"], force[force["phase"] == "load"]
    assert (np.diff(dl["force"]) > 0).all()          # np.interp needs an increasing load
    expected = np.interp(fl["force"], dl["force"], dl["indent"])
    assert np.abs(fl["indent"].to_numpy() - expected).max() <= p.step


def test_a_load_step_that_runs_out_of_tries_is_flagged():
    """max_rounds also caps the tries of a load step (tfm.protocol._load_to); a run whose
    steps run out of them is flagged, not reported as converged."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = tfm.simulate(Params(spacing=1 / 32, control="force", max_rounds=1, f_th=None, **STANDARD))
    assert res.summary["rounds_exceeded"] and "max_rounds=1" in res.summary["warnings"]


def test_a_load_step_that_runs_out_of_moves_says_so_not_max_rounds():
    """A contact softer than Hertz's (the local kernel) ran out of moves below its target
    load, and the flag blamed max_rounds, which raising could not help (a user's hunt)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = tfm.simulate(spacing="1/32", shape="paraboloid", k_th=0.02, max_indent=0.05, kernel="local",
                           c_w=30, control="force", load_step=0.0047450836, step=1e-4, extent=1.0)
    w = res.summary["warnings"]
    assert "load steps stopped below their target load" in w and "max_rounds" not in w
    assert not res.summary["rounds_exceeded"]
    assert res.summary["max_force"] < res.params.peak_load * (1 - 1e-3)     # it did fall short


def test_a_fine_step_under_a_coarse_load_step_reaches_the_load():
    """One load step of 0.0047 with step 2e-6 needs 25,000 moves of one step: max_rounds
    capped them, loading stopped at a quarter of max_load, and the jump-off was 20 % low,
    flagged as 'snap/enter rounds hit max_rounds'. The moves are capped by the depth now."""
    import warnings

    p = Params(spacing=1 / 32, control="force", max_load=0.004745, load_step=0.004745, step=2e-6,
               f_th=None, **{**STANDARD, "max_indent": "auto"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # the preload note of an explicit max_load
        s = tfm.simulate(p).summary
    assert s["max_force"] == pytest.approx(0.004745, rel=1e-8) and not s["rounds_exceeded"]
    # the jump-off of the default load steps (measured 0.0038354 at 1/32)
    assert s["jump_off_force"] == pytest.approx(0.0038354, rel=0.01)


def test_a_contact_that_closes_without_tension_has_no_jump_off():
    """Without adhesion the contact closes at P = 0: jump_off_force was -0.0 and its radius
    that of one spring touching at no load."""
    s = tfm.simulate(Params(spacing=1 / 32, control="force", f_th=0.0, k_th=None, alpha=0.0,
                            **{k: v for k, v in STANDARD.items() if k not in ("alpha", "k_th")})).summary
    assert np.isnan(s["jump_off_force"]) and np.isnan(s["jump_off_contact_radius"])


def test_the_step_guard_applies_under_force_control():
    """``step`` is the largest move of the flat while loading under force control too, so
    a coarse one sets the answer as it does under displacement control (1/32, step 0.02:
    21 springs at the first load step where finer moves take in 9); it ran unchecked."""
    from tfm.guards import check

    p = Params(control="force", step=0.01, f_th=None, **STANDARD)
    for control in ("force", "displacement"):
        with pytest.raises(ParameterError, match="step: only 5 loading steps"):
            check(p.replace(control=control))
    assert check(p.replace(step=0.005)) == []


def test_force_control_on_a_height_map_is_refused(tmp_path):
    """Its peak load was the Hertz load of a radius a height map does not have."""
    m = tmp_path / "m.npy"
    np.save(m, np.zeros((41, 41)))
    with pytest.raises(ParameterError, match="control: 'force' is not available for shape='height_map'"):
        Params(shape="height_map", height_map=str(m), spacing=1 / 32, f_th=0.0, alpha=0.0, control="force",
               max_indent=0.01, step=1e-3)
    # with a max_load too: "leave max_indent 'auto'" came first and led only to this refusal
    with pytest.raises(ParameterError, match="control: 'force' is not available for shape='height_map'"):
        Params(shape="height_map", height_map=str(m), spacing=1 / 32, f_th=0.0, alpha=0.0, control="force",
               max_load=1e-3, max_indent=0.01, step=1e-3)


def test_the_run_header_counts_the_flats_moves_under_force_control(capsys, tmp_path):
    """The header said "(100 loading steps)" for a load whose depth, 38, took 38,000 solves
    of at most `step` each: an hour's run announced as 100 steps (a user's hunt)."""
    from tfm.cli import main

    argv = ["run", "--spacing", "1/32", "--shape", "paraboloid", "--k-th", "0.02", "--control", "force",
            "--max-load", "0.01", "--step", "1e-3", "--no-plot", "-o", str(tmp_path / "x.parquet")]
    assert main(argv) == 0
    captured = capsys.readouterr()
    header = next(line for line in captured.err.splitlines() if line.startswith("tfm run "))
    # the printed summary has the jump-off's force, indent and radius (the indent was left out)
    import json
    printed = json.loads(captured.out)
    assert {"jump_off_force", "jump_off_indent", "jump_off_contact_radius"} <= set(printed)
    from tfm.results import read_metadata
    stored = read_metadata(tmp_path / "x.parquet")["summary"]
    assert printed["jump_off_indent"] == stored["jump_off_indent"] and np.isfinite(stored["jump_off_indent"])
    p = Params.from_dict(dict(spacing="1/32", shape="paraboloid", k_th=0.02, control="force", max_load=0.01,
                              step=1e-3))
    moves = int(np.ceil(p.delta_max / 1e-3 - 1e-9))
    assert moves > 10                                   # the Hertz depth of 0.01, in steps of 1e-3
    assert f"(100 load levels; the flat moves at most step=0.001 a solve: {moves:,} or more solves" in header


def test_a_small_preload_with_strong_adhesion_unloads_to_its_jump_off():
    """100 load levels to 1e-3, then steps of 1e-5 into tension: the pull-off (0.053 under
    displacement control) lies 5,300 unloading steps away, and the default cap of
    20 x 100 + 1000 stopped the run short of it, flagged, with NaN (a user's hunt).
    The cap now adds twice the continuum (JKR) pull-off in load steps."""
    from tfm.protocol import default_max_unload_steps

    body = dict(spacing=1 / 32, shape="paraboloid", k_th=0.3, step=1e-3)
    res = tfm.simulate(control="force", max_load=1e-3, **body)
    s = res.summary
    assert s["unload_complete"] and not s["warnings"]
    disp = tfm.simulate(max_indent=res.params.delta_max, **body).summary
    # as in test_jump_off_is_the_displacement_controlled_pull_off: within 1 %, and above
    assert disp["pull_off_force"] <= s["jump_off_force"] <= 1.01 * disp["pull_off_force"]
    p = res.params
    assert default_max_unload_steps(p) > s["n_steps"] > 20 * 100 + 1000
    assert default_max_unload_steps(Params.from_dict(dict(body, max_indent=0.01))) == 20 * 10 + 1000
    # a run that does hit the cap says what to raise
    with pytest.warns(tfm.RunWarning, match="raise max_unload_steps, or load_step"):
        short = tfm.simulate(control="force", max_load=1e-3, max_unload_steps=50, **body).summary
    assert not short["unload_complete"]
    assert ("unloading stopped at max_unload_steps with springs still in contact (after 50 unloading steps): "
            "raise max_unload_steps, or load_step") in short["warnings"]
