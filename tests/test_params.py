"""Bad input fails early, with a message naming the parameter and the allowed range."""
import math
import warnings

import pytest

from tfm import ParameterError, Params
from tfm.params import ParameterWarning, parse_number


@pytest.mark.parametrize("kw, match", [
    (dict(spacing=0), "spacing: must be > 0"),
    (dict(spacing=-1 / 64), "spacing: must be > 0"),
    (dict(spacing=math.nan), "spacing: must be finite"),
    # the extent given is named, not the spacing (a user's hunt: "spacing: must be <= ...")
    (dict(spacing=0.5, extent=0.1), "extent: the grid half-width 0.1 is smaller than the spacing 0.5"),
    (dict(k_th=-0.02, f_th=None), "k_th: must be >= 0"),
    (dict(f_th=-1e-5), "f_th: must be >= 0"),
    (dict(k_th=0.02, f_th=2e-5), "only one of k_th and f_th"),
    (dict(k_th=None, f_th=None), "give one threshold"),
    (dict(alpha=math.inf), "alpha: must be finite"),
    (dict(alpha=7.0), r"alpha: must be in \[-1, 3\]"),
    (dict(radius=0.0), "radius: must be > 0"),
    (dict(kernel="bousinesq"), "did you mean 'boussinesq'"),
    (dict(shape="cube"), "shape: unknown value 'cube'"),
    (dict(operator="fmm"), "operator: unknown value"),
    (dict(max_indent=2.0), "max_indent: must be < radius"),
    (dict(step=0.1, max_indent=0.05), "step: must be <= max_indent"),
    (dict(step=0.0), "step: must be > 0"),
    (dict(tol=0.5), r"tol: must be in \[1e-15, 1e-2\], got 0.5"),
    # CG's recursive residual fell on below rounding, and at 1e-200 divided by zero mid-run
    (dict(tol=1e-200), r"tol: must be in \[1e-15, 1e-2\], got 1e-200"),
    # at 1e300 a NumPy overflow in the solver was the only message, then a pull-off of 2e-299
    (dict(self_term=1e300), r"self_term: must be > 0 and <= 1e\+06, got 1e\+300"),
    (dict(neighbor_rings=0), r"neighbor_rings: must be in \[1, 64\]"),
    # K_IC^2 overflowed inside the automatic preload: an OverflowError naming nothing (fuzzing)
    (dict(k_th=1.3407807929942594e154, f_th=None), "max_indent: the automatic preload overflows for F_th"),
    (dict(radius=1e300, k_th=0.02, f_th=None), "max_indent: the automatic preload overflows .* radius 1e\\+300"),
    # the constructor said "allowed: none, events", leaving out the step count
    (dict(snapshots="every"), r"snapshots: expected 'none', 'events' or a whole number k >= 1 .*got 'every'"),
    (dict(neighbor_rings=1.5), "neighbor_rings: expected an integer"),
    (dict(layout="hexagonal"), "operator: 'fft' needs a regular square grid"),
    (dict(jitter=0.7, layout="jittered", operator="direct"), "jitter"),
    (dict(spacing=1e-5, extent=1.0), "would have 200001 springs a side"),
    # counts too long to read (150 digits) or to compute (math.ceil of inf raised)
    (dict(spacing=1 / 32, radius=1e300, max_indent=0.01, step=1e-3), r"would have 8\.32e\+150 springs a side"),
    (dict(spacing=1e-5, extent=1e308, max_indent=0.01, step=1e-3), "would have more than 1e\\+308 springs a side"),
])
def test_bad_values_are_refused_with_a_clear_message(kw, match):
    with pytest.raises(ParameterError, match=match):
        Params(**kw)


@pytest.mark.parametrize("name", ["max_iter", "max_rounds", "max_unload_steps"])
def test_iteration_caps_beyond_the_compiled_loops_int64_are_refused(name):
    # "1e19" read as a whole number overflowed int64 in the compiled loop: zero CG
    # iterations per solve (max_iter), a Numba error mid-run (max_rounds)
    for text in ("1e19", "1e20", str(2 ** 31)):
        with pytest.raises(ParameterError, match=rf"{name}: must be in \[1, 2147483647\], got"):
            Params.from_dict({name: text})
    assert getattr(Params.from_dict({name: str(2 ** 31 - 1)}), name) == 2 ** 31 - 1


def test_from_dict_accepts_fractions_and_names_unknown_keys():
    p = Params.from_dict({"spacing": "1/64", "k_th": "0.02", "max_indent": "auto"})
    assert p.spacing == 1 / 64 and p.k_th == 0.02 and p.f_th is None
    assert p.delta_max > 0
    with pytest.raises(ParameterError, match="unknown parameter 'k_t'.*did you mean 'k_th'"):
        Params.from_dict({"k_t": 0.02}, where="file.toml")
    with pytest.raises(ParameterError, match="spacing: cannot read '1/x'"):
        Params.from_dict({"spacing": "1/x"})
    with pytest.raises(ParameterError, match=r"spacing: cannot read '1/0' as a number \(division by zero\)"):
        Params.from_dict({"spacing": "1/0"})


def test_parse_number_forms():
    assert parse_number("1/256", "s") == 1 / 256
    assert parse_number(" 2e-5 ", "s") == 2e-5
    with pytest.raises(ParameterError):
        parse_number(True, "s")


def test_run_id_is_stable_and_parameter_sensitive():
    a = Params(spacing=1 / 64)
    assert a.run_id == Params.from_dict({"spacing": "1/64"}).run_id
    assert a.run_id != Params(spacing=1 / 32).run_id
    assert len(a.run_id) == 16


def test_threshold_and_defaults_follow_the_paper():
    p = Params()  # the paper's Fig. 3 case
    assert (p.spacing, p.f_th, p.radius, p.shape, p.self_term) == (1 / 128, 2e-5, 1.0, "sphere", 3.8)
    q = Params(k_th=0.02, f_th=None, alpha=0.75, spacing=1 / 64)
    assert q.threshold_force == pytest.approx(0.02 * (1 / 64) ** 1.5)


def test_params_are_frozen():
    p = Params()
    with pytest.raises(Exception):
        p.spacing = 0.1


def test_none_is_no_value_for_optional_parameters_and_a_value_of_choices(tmp_path):
    """"none" (TOML, the command line) means "no value" for an optional parameter, but it is
    itself a value of preconditioner and threshold_disorder: it was turned into None there
    too, and preconditioner = "none", a documented value, was refused by tfm run and by
    campaigns ('unknown value None')."""
    from tfm.campaign import select_runs, spec_from_dict
    from tfm.cli import main
    from tfm.results import read_metadata

    p = Params.from_dict({"preconditioner": "none", "threshold_disorder": "None", "f_th": "none", "k_th": 0.02,
                          "extent": "null"})
    assert (p.preconditioner, p.threshold_disorder, p.f_th, p.extent) == ("none", "none", None, None)
    with pytest.raises(ParameterError, match="radius: cannot read 'none' as a number"):
        Params.from_dict({"radius": "none"})
    spec = spec_from_dict({"name": "t", "base": {"spacing": "1/16", "k_th": 0.02, "preconditioner": "none",
                                                  "step": 2e-3},
                           "sweep": {"extent": [0.8, "none"]}})
    assert [r.params.preconditioner for r in spec.runs] == ["none", "none"]
    assert [r.params.extent for r in select_runs(spec, ["extent=none"])] == [None]
    out = tmp_path / "c.parquet"
    assert main(["run", "--spacing", "1/16", "--k-th", "0.02", "--step", "2e-3", "--preconditioner", "none",
                 "--f-th", "None", "--no-plot", "-q", "-o", str(out)]) == 0
    assert Params.from_dict(read_metadata(out)["params"]).preconditioner == "none"


def test_replace_reads_values_like_from_dict_and_either_threshold_clears_the_other():
    """replace(spacing="1/32") was refused ('expected a number') though simulate(spacing=
    "1/32") takes it, and replace(f_th=...) on a k_th record said 'give only one'."""
    p = Params.from_dict({"k_th": 0.02})
    assert p.replace(spacing="1/32").spacing == 1 / 32
    q = p.replace(f_th=1e-5)
    assert (q.f_th, q.k_th) == (1e-5, None)
    assert q.replace(k_th=0.03).f_th is None
    with pytest.raises(ParameterError, match=r"Params\(k_th=..., f_th=None\)"):
        Params(k_th=0.02)


def test_the_package_lists_its_entry_points():
    import tfm

    assert {"simulate", "RunWarning", "Params"} <= set(dir(tfm))


def test_simulate_refuses_arguments_it_would_ignore(tmp_path):
    import tfm

    with pytest.raises(ParameterError, match="fields_path: applies only with snapshots"):
        tfm.simulate(spacing=1 / 16, k_th=0.02, step=2e-3, fields_path=tmp_path / "x.fields.nc")
    with pytest.raises(ParameterError, match="checkpoint_every: applies only with a checkpoint"):
        tfm.simulate(spacing=1 / 16, k_th=0.02, step=2e-3, checkpoint_every=5)
    # slips that failed late or with a stranger's error (AttributeError: 'dict' object has
    # no attribute 'units'; TypeError after the first step; FileNotFoundError mid-run)
    with pytest.raises(ParameterError, match="progress: expected a function of one step record, got 1"):
        tfm.simulate(spacing=1 / 16, k_th=0.02, step=2e-3, progress=1)
    with pytest.raises(ParameterError, match="fields_path: the folder of .* does not exist"):
        tfm.simulate(spacing=1 / 16, k_th=0.02, step=2e-3, snapshots="events",
                     fields_path=tmp_path / "nowhere" / "x.fields.nc")
    with pytest.raises(ParameterError, match="simulate: expected a tfm.Params or a dict of parameters, got list"):
        tfm.simulate([1 / 16])
    # a checkpoint folder that cannot take the file failed at the first save, 10 min in
    with pytest.raises(ParameterError, match="checkpoint: cannot write the folder /proc"):
        tfm.simulate(spacing=1 / 16, k_th=0.02, step=2e-3, checkpoint="/proc/run.npz")
    assert not list(tmp_path.iterdir())
    as_dict = dict(spacing="1/16", k_th=0.02, step=2e-3, max_indent=0.05)
    assert tfm.simulate(as_dict, alpha=0.5).params == Params.from_dict({**as_dict, "alpha": 0.5})


# ---- found by a user-style hunt for silently accepted input (2026-11-24) ------------------
ROUGH = dict(spacing="1/32", k_th=0.02, shape="paraboloid", max_indent=0.05, step=1e-3, rms_height=1e-3)


@pytest.mark.parametrize("kw, match", [
    # fourier_synthesis raised "no wavevector between the cutoffs" mid-setup, with a traceback
    (dict(ROUGH, short_cutoff=10.0), r"short_cutoff: must be <= the grid side \(0\.90625\)"),
    # the grid's automatic preload was 10 steps and the guard advised "Use step <= 0"
    (dict(spacing="1/128", f_th=0.0, shape="paraboloid"), "max_indent: 'auto' sizes the preload by the adhesion"),
    # rolloff sets the PSD below long_cutoff only: without it, three values drew one surface
    (dict(ROUGH, extent=0.5, rolloff=0.3), "rolloff: 0.3 has no effect here; it applies only when the surface "
                                          "is rough and long_cutoff is given"),
    # long_cutoff at the grid side leaves no mode below q_L: rolloff 0 and 1 drew one surface
    (dict(ROUGH, extent=0.75, long_cutoff="49/32", rolloff=0.0),
     r"rolloff: 0.0 has no effect here: long_cutoff 1.53125 is the grid side"),
    # a grid narrower than the default short cutoff: a TypeError formatting long_cutoff None
    (dict(ROUGH, shape="flat_punch", radius=0.05, k_th=None, f_th=0.0, extent="1/32", max_indent=0.01, step=1e-4),
     r"short_cutoff: the grid \(side 0\.09375\) is narrower than the default short cutoff, 4 spacings = 0\.125"),
    # a seed beyond int64 computed, and then no campaign table could ever be written
    (dict(ROUGH, roughness_seed=2 ** 64 + 1), r"roughness_seed: must be in \[0, 9223372036854775807\]"),
    # force control: 1e10 load steps started; the depth's errors named max_indent, not max_load
    (dict(ROUGH, rms_height=0.0, control="force", max_indent=0.05, load_step=1e-12),
     r"load_step: the peak load / load_step = 4\.\d+e\+09 load steps; must be <= 1e\+06"),
    (dict(ROUGH, rms_height=0.0, max_indent="auto", control="force", max_load=1e-12),
     r"step: must be <= the depth of max_load 1e-12.*; lower step or raise max_load$"),
])
def test_input_that_ran_or_crashed_is_refused_before_computing(kw, match):
    with pytest.raises(ParameterError, match=match):
        Params.from_dict(kw)


def test_a_rough_surface_runs_under_force_control_with_a_max_load():
    """'auto' was refused for a rough body ('give a number') and a number refused under
    force control with a max_load ('leave max_indent auto'): no way to run it. With a
    max_load, 'auto' is that load's depth, which only sizes the grid."""
    p = Params.from_dict(dict(ROUGH, max_indent="auto", control="force", max_load=0.01, extent=0.5))
    assert p.delta_max > 0


def test_integers_given_as_text_are_read_exactly():
    """'9007199254740993' went through a float and became ...992 (another run id than the
    same seed written as a number)."""
    kw = dict(spacing="1/32", k_th=0.02, threshold_disorder="uniform", disorder_width=0.2)
    assert Params.from_dict({**kw, "disorder_seed": "9007199254740993"}).disorder_seed == 2 ** 53 + 1
    for text in ("9007199254740993.0", "9.007199254740993e15"):
        assert Params.from_dict({**kw, "disorder_seed": text}).disorder_seed == 2 ** 53 + 1
    with pytest.raises(ParameterError, match="disorder_seed: expected a whole number, got '1.5'"):
        Params.from_dict({**kw, "disorder_seed": "1.5"})
    assert (Params.from_dict({**kw, "disorder_seed": "12"}).run_id
            == Params.from_dict({**kw, "disorder_seed": 12}).run_id)


@pytest.mark.parametrize("kw, names", [
    (dict(k_th=0.0, alpha=0.5), ["alpha"]),
    (dict(f_th=0.0, threshold_disorder="weibull", disorder_width=0.3), ["threshold_disorder", "disorder_width"]),
])
def test_values_that_change_nothing_without_adhesion_are_warned_about(kw, names):
    """With every threshold zero, the exponent and a disorder around it do nothing, yet
    gave other run ids without a word. Warned, not refused: a campaign may sweep k_th
    through 0 with the rest fixed."""
    with pytest.warns(ParameterWarning) as caught:
        Params.from_dict(dict(spacing="1/32", shape="paraboloid", max_indent=0.05, step=1e-3, **kw))
    said = [str(w.message) for w in caught]
    for name in names:
        assert f"{name}: given but has no effect here: every threshold is zero (no adhesion)" in said


def test_a_seed_without_jitter_is_warned_about():
    """layout='jittered' with jitter 0 is the square grid: a seed gave another run id and
    the same curve, without a word (a hunt). Warned, not refused: a campaign may sweep the
    jitter through 0 with its seeds."""
    kw = dict(spacing="1/32", k_th=0.02, shape="paraboloid", max_indent=0.05, step=1e-3, layout="jittered",
              operator="direct", jitter=0.0)
    with pytest.warns(ParameterWarning, match=r"seed: given but has no effect here: jitter is 0"):
        Params.from_dict(dict(kw, seed=5))
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # the default seed, or a jitter: nothing to say
        Params.from_dict(kw)
        Params.from_dict(dict(kw, jitter=0.1, seed=5))


def test_a_threshold_override_clears_the_other_one_for_a_dict_as_for_a_record():
    """simulate(dict with k_th, f_th=...) was refused with "give only one", while the
    same call with a Params record replaced k_th (a user's hunt)."""
    import tfm

    from pathlib import Path

    as_dict = dict(spacing="1/16", k_th=0.02, step=2e-3, max_indent=0.05, shape="paraboloid")
    via_dict = tfm.simulate(as_dict, f_th=2e-4).params         # a_c = 2.3 spacings: resolved
    assert via_dict == tfm.simulate(Params.from_dict(as_dict), f_th=2e-4).params
    assert via_dict.k_th is None and via_dict.f_th == 2e-4
    with pytest.raises(ParameterError, match="expected a tfm.Params or a dict of parameters, got PosixPath"):
        tfm.simulate(Path("run.toml"))


def test_submodules_are_attributes_after_a_bare_import():
    """`import tfm; tfm.results.read_metadata(...)`, as the docs write it, raised
    AttributeError in a fresh interpreter."""
    import subprocess
    import sys

    code = ("import tfm; print(tfm.results.read_metadata.__name__, tfm.analysis.ensemble_stats.__name__, "
            "tfm.theory.__name__, callable(tfm.simulate))\n"
            "try:\n    tfm.no_such_thing\nexcept AttributeError as e:\n    print('AttributeError')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["read_metadata", "ensemble_stats", "tfm.theory", "True", "AttributeError"]


def test_the_physics_sheet_lists_where_every_parameter_applies():
    """docs/physics.md's table of where each parameter has an effect had lost max_load and
    load_step, and theta's kernel condition."""
    from pathlib import Path

    from tfm.params import APPLIES

    sheet = (Path(__file__).resolve().parents[1] / "docs" / "physics.md").read_text()
    rows = [line for line in sheet.splitlines() if line.startswith("| `")]
    for name in APPLIES:
        assert any(f"`{name}`" in row.split("|")[1] for row in rows), name
    theta = next(row for row in rows if row.startswith("| `theta`"))
    assert "boussinesq" in theta


def test_snapshots_read_like_every_other_whole_number():
    """From a file or a dict, snapshots = "5.0" gave 5 while 5.0 (a TOML float) was refused;
    every other whole-number parameter takes both."""
    kw = dict(spacing="1/32", k_th=0.02)
    assert Params.from_dict({**kw, "max_iter": 2000.0}).max_iter == 2000
    for value in (5, "5", "5.0", 5.0):
        assert Params.from_dict({**kw, "snapshots": value}).snapshots == 5
    for value in (2.5, "2.5"):
        with pytest.raises(ParameterError, match="snapshots: expected"):
            Params.from_dict({**kw, "snapshots": value})
    with pytest.raises(ParameterError, match="snapshots: expected an integer, got True"):
        Params.from_dict({**kw, "snapshots": True})


def test_a_loose_tree_opening_angle_is_a_note_of_the_run():
    """theta up to 1 was accepted silently, though its error bound there is 103 % of
    sum |f|/r and the pull-off indent moved 18 steps against the direct sum (spacing 1/48,
    a user's hunt); 0.7 is the largest angle that kept the pull-off within 1e-5. It was
    then a ParameterWarning of from_dict alone: not in the summary's warnings, exit 0, and
    nothing from Params(...) or replace. Now it is a note of the run, on every path."""
    from tfm.guards import check

    base = dict(spacing="1/48", k_th=0.02, shape="paraboloid", max_indent=0.05, operator="tree")
    notes = check(Params.from_dict(dict(base, theta=1.0)), memory=False)
    assert len(notes) == 1 and notes[0].startswith("theta: 1 is loose: the tree's error bound is 103 % of sum |f|/r")
    assert check(Params.from_dict(dict(base, theta=0.7)), memory=False) == []
    assert check(Params.from_dict(dict(base, theta=0.7)).replace(theta=1.0), memory=False) == notes


def test_replace_and_simulate_advise_like_from_dict():
    """A parameter without effect was warned about only by from_dict: replace(theta=0.5)
    with the FFT operator, simulate(p, jitter=0.25) and simulate(p.to_dict(), jitter=0.25)
    said nothing. Checked without running: simulate refuses the bad progress argument
    after the parameters."""
    from tfm import simulate

    base = dict(spacing=1 / 48, k_th=0.02, f_th=None, shape="paraboloid", max_indent=0.05)
    fft = Params.from_dict(base)
    with pytest.warns(ParameterWarning, match="theta: given but has no effect; it applies only when "
                                              "operator='tree'") as caught:
        fft.replace(theta=0.5)
    assert caught[0].filename == __file__
    # (a Params(...) with a non-default jitter is refused: a default given explicitly is
    # what can have no effect, and a record built directly cannot tell it was given)
    for args, over in (((fft,), dict(jitter=0.25)), ((fft.to_dict(),), dict(jitter=0.25))):
        with pytest.warns(ParameterWarning, match="jitter: given but has no effect") as caught, \
                pytest.raises(ParameterError, match="progress"):
            simulate(*args, **over, progress=5)
        assert caught[0].filename == __file__


def test_simulate_turns_a_record_to_si_units_and_refuses_what_is_no_record():
    """simulate(Params(...), units='si', work_of_adhesion=...) kept the paper-units default
    f_th and failed with "not both" thresholds; a table row gave an AttributeError; a
    mistyped keyword of simulate's own got no hint."""
    import inspect

    import pandas as pd

    from tfm import simulate
    from tfm.simulate import KEYWORDS

    si = dict(units="si", youngs_modulus=1e6, poisson_ratio=0.5, work_of_adhesion=0.05, radius=1e-3,
              spacing=3.4e-6, step=1e-8)
    assert Params(shape="paraboloid").replace(**si) == Params.from_dict({"shape": "paraboloid", **si})
    with pytest.raises(ParameterError, match=r"got Series \(a table row: tfm.Params.from_row\(row\)\)"):
        simulate(pd.Series({"p_spacing": 0.1}))
    with pytest.raises(ParameterError, match="unknown parameter 'progres' \\(did you mean 'progress'\\?\\)"):
        simulate(progres=print)
    assert set(KEYWORDS) == set(inspect.signature(simulate).parameters) - {"p", "overrides"}
    assert Params.from_dict({"max_indent": " Auto "}).max_indent == "auto"


def test_a_name_in_the_wrong_case_gets_its_hint():
    """'tre' got "did you mean 'tree'?", 'FFT' got no hint. The record itself holds the
    values as the docs write them, so a direct construction is still refused."""
    with pytest.raises(ParameterError, match=r"operator: unknown value 'FFT'.*did you mean 'fft'\?"):
        Params(operator="FFT")


def test_loose_input_reads_choices_case_blind():
    """`tfm run --units SI` and `--snap-rule Batch` were refused with a hint (a user's
    hunt); the command line, TOML and from_dict now read them as 'si' and 'batch', the
    same run as the lower-case spelling."""
    from tfm.params import _KINDS, CHOICES

    si = dict(youngs_modulus=1e6, poisson_ratio=0.5, work_of_adhesion=0.05, radius=1e-3,
              spacing=3.4e-6, step=1e-8)
    loose = Params.from_dict(dict(si, units="SI", snap_rule="Batch", shape=" Paraboloid ",
                                  operator="FFT", kernel="Boussinesq", layout="Square",
                                  preconditioner="Auto", control="Displacement",
                                  threshold_disorder="None"))
    exact = Params.from_dict(dict(si, units="si", snap_rule="batch", shape="paraboloid"))
    assert loose == exact and loose.run_id == exact.run_id
    # every text field with a fixed set of values is read this way
    assert set(CHOICES) == {name for name, kind in _KINDS.items() if kind == "str"} - {
        "height_map", "height_map_hash", "allow"}
    with pytest.raises(ParameterError, match=r"units: unknown value 'S I'"):
        Params.from_dict(dict(units="S I"))
    # k_th_coefficient's names too ('JKR' was refused with "did you mean 'jkr'?")
    for name in ("JKR", " Paper ", "LIMIT"):
        named = Params.from_dict(dict(si, units="si", k_th_coefficient=name))
        assert named == Params.from_dict(dict(si, units="si", k_th_coefficient=name.strip().lower()))


def test_minus_zero_is_the_same_run_as_zero():
    """k_th = [0.0, -0.0] in a campaign made two runs with one result: the run id hashed
    the JSON, which keeps the sign of zero (a user's hunt)."""
    import numpy as np

    base = dict(spacing="1/16", shape="paraboloid", step=2e-3, max_indent=0.05)
    ids = {Params.from_dict(dict(base, k_th=k)).run_id for k in (0.0, -0.0, np.float64(-0.0), 0)}
    assert len(ids) == 1
    assert math.copysign(1.0, Params.from_dict(dict(base, k_th=-0.0)).k_th) == 1.0


def test_a_single_precision_value_is_the_run_of_the_number_it_prints():
    """np.float32(0.1) as max_load made another run than 0.1: its float is
    0.10000000149..., though it prints, and was meant, as 0.1 (a user's hunt)."""
    import numpy as np

    base = dict(spacing="1/16", shape="paraboloid", k_th=0.02, control="force", step=2e-3)
    plain = Params.from_dict(dict(base, max_load=0.1))
    single = Params.from_dict(dict(base, max_load=np.float32(0.1)))
    assert single.max_load == 0.1 and type(single.max_load) is float
    assert single.run_id == plain.run_id


def test_clearing_a_parameter_when_it_stops_applying_is_no_warning():
    """replace(control="displacement", max_load=None) on a force-controlled record warned
    "max_load: given but has no effect": None clears it, back to its default."""
    base = dict(spacing="1/16", shape="paraboloid", k_th=0.02, step=2e-3)
    force = Params.from_dict(dict(base, control="force", max_load=0.01))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = force.replace(control="displacement", max_load=None)
    assert back == Params.from_dict(dict(base, max_indent=back.max_indent))
    # a value that has no effect is still refused, and a default given is still warned
    with pytest.warns(ParameterWarning, match="max_load: given but has no effect"):
        Params.from_dict(dict(base, max_load=None))


def test_extent_auto_is_the_automatic_extent():
    """The README's table gives extent's default as auto, but 'auto' was refused as not a
    number (a user's hunt)."""
    base = dict(spacing="1/32", k_th=0.02, shape="paraboloid", max_indent=0.05)
    assert Params.from_dict(dict(base, extent="auto")) == Params.from_dict(base)
    assert Params.from_dict(dict(base, extent="none")).extent is None
