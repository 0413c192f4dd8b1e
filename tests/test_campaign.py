"""Campaigns: TOML -> validated runs -> Parquet tables; resume, failures, Dask, bitwise equality.

The campaign used throughout is campaigns/smoke.toml (6 coarse runs, a few seconds).
"""
from __future__ import annotations

import importlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import tfm
import tfm.checkpoint as tfm_checkpoint
from tfm.campaign import (CampaignError, CampaignStore, load_failures, load_spec, load_tables,
                          run_campaign, spec_from_dict)
from tfm.cli import main as tfm_main
from tfm.config import SCHEMA_VERSION
from tfm.params import ParameterWarning, Params
from tfm.results import CURVE_COLUMNS, read_metadata

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "campaigns" / "smoke.toml"
N_SMOKE = 6

# Columns that legitimately differ between two executions of the same run.
VOLATILE = ("r_wall_time",)


def result_view(summary: pd.DataFrame) -> pd.DataFrame:
    """The columns a run's parameters alone must determine: ids, params, results."""
    cols = [c for c in summary.columns if not c.startswith("prov_") and c not in VOLATILE]
    return summary[cols].reset_index(drop=True)


def assert_bitwise_equal(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Same columns, same dtypes, and float columns equal bit for bit (not to a tolerance)."""
    assert list(a.columns) == list(b.columns)
    assert len(a) == len(b)
    for col in a.columns:
        assert a[col].dtype == b[col].dtype, col
        x, y = a[col].to_numpy(), b[col].to_numpy()
        if x.dtype.kind == "f":
            differ = x.view(np.uint64) != y.view(np.uint64)
            assert not differ.any(), (f"{col}: {differ.sum()} values differ, first at row "
                                      f"{np.argmax(differ)}: {x[differ][0]!r} vs {y[differ][0]!r}")
        else:
            assert a[col].equals(b[col]), col


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    """The smoke campaign, uninterrupted, in this process (--jobs 1)."""
    results = tmp_path_factory.mktemp("serial")
    root = run_campaign(SMOKE, jobs=1, quiet=True, results_dir=results)
    return results, root


# ---- expansion and validation ------------------------------------------------
def test_expansion_is_stable_and_zips_move_together():
    a, b = load_spec(SMOKE), load_spec(SMOKE)
    assert a.run_ids == b.run_ids
    assert len(a.runs) == N_SMOKE == len(set(a.run_ids))
    assert [r.run_id for r in a.runs] == [r.params.run_id for r in a.runs]
    pairs = {(r.params.radius, r.params.max_indent) for r in a.runs}
    assert pairs == {(1.0, 0.05), (2.0, 0.1), (4.0, 0.2)}        # zipped, not crossed
    assert {r.params.alpha for r in a.runs} == {0.5, 0.75}
    assert all(r.params.spacing == 1 / 16 and r.params.f_th is None for r in a.runs)


def test_sweep_axes_come_before_zip_groups_wherever_the_file_puts_them(tmp_path):
    """The README said "in file order", but a [[zip]] above [sweep] still varies fastest:
    the documented order is [sweep] axes, then [[zip]] groups, whatever the layout."""
    text = ('name = "order"\n[base]\nspacing = "1/32"\nk_th = 0.04\nshape = "paraboloid"\n'
            'max_indent = 0.1\n[[zip]]\nradius = [1.0, 2.0]\n[sweep]\nalpha = [0.5, 0.75]\n')
    spec = load_spec(_write(tmp_path, text))
    assert [(r.params.alpha, r.params.radius) for r in spec.runs] == [(0.5, 1.0), (0.5, 2.0),
                                                                       (0.75, 1.0), (0.75, 2.0)]


def test_rough_sphere_description_counts_its_own_runs():
    """Its description said 4 seeds and a smooth run the file does not have."""
    spec = load_spec(REPO / "campaigns" / "rough_sphere.toml")
    seeds = len(spec.sweep["roughness_seed"])
    assert f"{seeds} roughness seeds each" in spec.description
    assert f"{len(spec.runs)} runs" in spec.description
    assert all(r.params.rms_height > 0 for r in spec.runs)       # the smooth sphere is not a run


def test_run_id_is_the_params_hash_with_schema_version():
    spec = spec_from_dict({"name": "x", "base": {"spacing": "1/256", "k_th": 0.02, "shape": "paraboloid",
                                                 "max_indent": 0.01, "step": 1e-3}})
    (run,) = spec.runs
    assert run.params.spacing == 1 / 256                              # fractions accepted
    assert run.run_id == Params.from_dict(dict(spacing=1 / 256, k_th=0.02, shape="paraboloid",
                                               max_indent=0.01, step=1e-3)).run_id


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


BASE = 'name = "bad"\n[base]\nspacing = "1/32"\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.025\n'


@pytest.mark.parametrize("text, expected", [
    (BASE + "[sweep]\nalpah = [0.5, 0.75]\n", ["[sweep]", "unknown parameter 'alpah'", "did you mean 'alpha'"]),
    (BASE.replace("spacing", "spacng"), ["[base]", "'spacng'", "did you mean 'spacing'"]),
    (BASE + "[sweep]\nalpha = [0.5, 5]\n", ["run 1 (alpha=5)", "alpha: must be in [-1, 3]"]),
    (BASE + "[sweep]\nkernel = ['local', 'bousinesq']\n", ["run 1", "kernel: unknown value", "did you mean 'boussinesq'"]),
    (BASE + "[sweep]\nstep = ['1/0']\n", ["step", "cannot read '1/0' as a number"]),
    ("descripton = 'x'\n" + BASE, ["unknown top-level key 'descripton'", "did you mean 'description'"]),
    (BASE + "description = 'x'\n", ["[base]: 'description' is a top-level key", "before the first [table]"]),
    # a top-level key after a table: it said "unknown parameter 'sweep' (did you mean
    # 'step'?)", and "[sweep] max_runs: a swept parameter needs a list of values"
    (BASE + "sweep = [1]\n", ["[base]: 'sweep' is a top-level key", "or as a table of its own, [sweep]"]),
    (BASE + "[sweep]\nalpha = [0.5]\nmax_runs = 3\n", ["[sweep]: 'max_runs' is a top-level key",
                                                        "before the first [table]"]),
    (BASE + "[[zip]]\nalpha = [0.5]\nzip = 3\n", ["[[zip]] #1: 'zip' is a top-level key", "[[zip]]"]),
    # it said "name: expected a folder-safe name ..., got None"
    (BASE.replace('name = "bad"\n[base]\n', '[base]\nname = "bad"\n'),
     ["name: found inside [base]", "must come before the first [table]"]),
    (BASE.replace('"bad"', '"../up"'), ["name", "folder-safe"]),
    ('description = "no name"\n', ["missing key 'name'", "results/<name>/"]),
    (BASE + "[sweep]\nalpha = 0.5\n", ["[sweep] alpha", "needs a list"]),
    (BASE + "[sweep]\nalpha = []\n", ["[sweep] alpha", "empty list"]),
    (BASE + "[[zip]]\nradius = [0.5, 1.0]\nstep = [1e-3]\n", ["[[zip]] #1", "same length", "radius has 2"]),
    (BASE + "[sweep]\nspacing = ['1/32', '1/64']\n", ["'spacing' is set in both [base] and [sweep]"]),
    (BASE + "[sweep]\nradius = [0.5, 0.50]\n", ["run 1", "same run as run 0"]),
    (BASE + "[sweep\nalpha = [1]\n", ["not valid TOML"]),
])
def test_malformed_campaign_files_fail_clearly(tmp_path, text, expected):
    path = _write(tmp_path, text)
    with pytest.raises(CampaignError) as info:
        load_spec(path)
    message = str(info.value)
    assert message.startswith(str(path)), message                     # names the file
    for part in expected:
        assert part in message, message


def test_cli_reports_a_bad_file_and_runs_nothing(tmp_path, capsys):
    path = _write(tmp_path, BASE + "[sweep]\nalpha = [0.5, 7]\n")
    assert tfm_main(["campaign", "run", str(path), "--results-dir", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "alpha: must be in [-1, 3]" in err
    assert not (tmp_path / "res").exists()                            # validated before anything ran


def test_a_direct_run_of_weeks_is_refused_before_the_campaign_starts(tmp_path, capsys):
    """A campaign's direct-sum run estimated at weeks started among the others and failed
    as a run of its own (the cost guard is this machine's, so campaign files skip it).
    Now `campaign run` refuses it before any run, naming it and its override."""
    text = BASE.replace('"1/32"', '"1/2048"').replace("max_indent = 0.025", "max_indent = 0.5\nstep = 1e-2") \
        + 'operator = "direct"\n[sweep]\nalpha = [0.5, 0.75]\n'
    path = _write(tmp_path, text)
    assert len(load_spec(path).runs) == 2                             # the file itself is valid
    assert tfm_main(["campaign", "run", str(path), "--results-dir", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert f"{path}: run 0 " in err and "the direct sum over" in err and 'allow = "cost"' in err
    assert "--allow" not in err and err.count("to run it anyway") == 1     # the file's advice, once
    assert not list((tmp_path / "res").rglob("*.parquet"))            # nothing ran
    allowed = text.replace('operator = "direct"', 'operator = "direct"\nallow = "cost"')
    path.write_text(allowed)
    from tfm.campaign.runner import _check_cost
    _check_cost(load_spec(path), load_spec(path).runs)               # allowed: no refusal


def test_missing_file(tmp_path):
    with pytest.raises(CampaignError, match="no such campaign file"):
        load_spec(tmp_path / "nope.toml")


# ---- tables --------------------------------------------------------------------
def test_tables_have_expected_columns_and_rows(serial_run):
    results, root = serial_run
    summary, curves = load_tables("smoke", results_dir=results)
    spec = load_spec(SMOKE)
    assert summary["run_id"].tolist() == spec.run_ids                  # expansion order, once each
    assert (summary["status"] == "ok").all()
    assert list(summary.columns[:2]) == ["run_id", "status"]
    assert [c for c in summary.columns if c.startswith("p_")] == ["p_" + n for n in Params.field_names()]
    for col in ("r_pull_off_force", "r_pull_off_indent", "r_max_contact_radius", "r_n_solves",
                "r_solver_iters", "r_wall_time", "r_contact_reached_edge", "r_solver_not_converged",
                "prov_tfm_version", "prov_git_commit", "prov_code_hash", "prov_numba_version", "prov_numpy_version",
                "prov_host", "prov_started_at", "prov_numba_threads"):
        assert col in summary.columns, col
    assert all(c in ("run_id", "status", "fields_path") or c.split("_", 1)[0] in ("p", "r", "prov") for c in summary.columns)
    assert summary["p_max_indent"].tolist() == ["0.05", "0.1", "0.2"] * 2
    assert summary["r_max_indent"].tolist() == [0.05, 0.1, 0.2] * 2
    assert (summary["r_pull_off_force"] > 0).all()

    assert list(curves.columns) == ["run_id"] + CURVE_COLUMNS
    assert len(curves) == summary["r_n_steps"].sum()
    assert curves["run_id"].drop_duplicates().tolist() == spec.run_ids
    assert (curves.groupby("run_id", sort=False).size().to_numpy() == summary["r_n_steps"].to_numpy()).all()
    assert len(load_failures("smoke", results_dir=results)) == 0

    for table in ("summary", "curves", "failures"):
        meta = read_metadata(root / f"{table}.parquet")
        assert meta["schema_version"] == SCHEMA_VERSION
        assert meta["campaign"]["run_ids"] == spec.run_ids
    # a plain pyarrow reader sees the same table
    assert pq.read_table(root / "summary.parquet").num_rows == N_SMOKE


def test_rerun_does_no_work(serial_run, monkeypatch):
    results, root = serial_run
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*.parquet")}

    def boom(*args, **kwargs):
        raise AssertionError("a finished run was run again")

    monkeypatch.setattr("tfm.campaign.runner.execute", boom)
    assert run_campaign(SMOKE, jobs=2, quiet=True, results_dir=results) == root
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*.parquet")} == before


def test_runs_from_other_code_are_reported_stale_and_can_be_rerun(tmp_path, monkeypatch, capsys):
    """The run id hashes parameters, not code: resume must say when stored runs came from
    other source code, and --rerun-stale must recompute them. Other code is another hash
    of tfm's files: runs from uncommitted edits (the same commit, '-dirty') were not
    stale, and every commit, even one that left tfm/ alone, made all runs stale."""
    spec = spec_from_dict({"name": "stale", "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                     "max_indent": 0.05, "step": 5e-3},
                           "sweep": {"alpha": [0.5, 0.75]}}, source="stale")
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    assert store.status(spec).stale == []
    monkeypatch.setattr("tfm.campaign.store.loaded_commit", lambda: "0" * 40)    # tfm/ untouched
    assert store.status(spec).stale == []
    monkeypatch.setattr("tfm.campaign.store.code_hash", lambda: "0" * 64)        # tfm/ edited
    assert len(store.status(spec).stale) == 2
    calls = []
    real = importlib.import_module("tfm.campaign.runner").execute
    monkeypatch.setattr("tfm.campaign.runner.execute", lambda *a, **k: calls.append(1) or real(*a, **k))
    run_campaign(spec, results_dir=tmp_path)
    err = capsys.readouterr().err
    assert calls == [] and "computed by other tfm source code" in err
    assert "nothing to run, 2 of 2 runs already done" in err          # it said nothing at all
    run_campaign(spec, results_dir=tmp_path, rerun_stale=True)
    assert len(calls) == 2
    # the recomputed runs were counted as done and as already done ("6 ... 6 already done")
    assert "2 runs done, 0 failed, 0 already done" in capsys.readouterr().err
    # stale runs left out by a selection were counted as already done and as not selected
    # ("2 runs done, 0 failed, 6 already done, 6 not selected" of 8: a user's hunt)
    monkeypatch.setattr("tfm.campaign.store.code_hash", lambda: "1" * 64)
    run_campaign(spec, results_dir=tmp_path, rerun_stale=True, only=[spec.runs[0].run_id])
    assert "1 run done, 0 failed, 0 already done, 1 not selected" in capsys.readouterr().err
    run_campaign(spec, results_dir=tmp_path, only=[spec.runs[0].run_id])
    assert "nothing to run, 2 of 2 runs already done" in capsys.readouterr().err


def test_runs_computed_by_other_code_are_reported_as_they_arrive(tmp_path, monkeypatch, capsys):
    """A Dask cluster running another version of tfm filled the tables in silence: its
    runs were stale as soon as they were stored (and --rerun-stale on the same cluster
    made them stale again). Here the workers' other code is a result's provenance."""
    spec = spec_from_dict({"name": "elsewhere", "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                         "max_indent": 0.05, "step": 5e-3},
                           "sweep": {"alpha": [0.5, 0.75]}}, source="elsewhere")
    real = importlib.import_module("tfm.campaign.runner").execute

    def other_code(*args, **kwargs):
        outcome = real(*args, **kwargs)
        outcome.result.provenance["code_hash"] = "0" * 64
        return outcome

    monkeypatch.setattr("tfm.campaign.runner.execute", other_code)
    run_campaign(spec, results_dir=tmp_path, quiet=True)
    err = capsys.readouterr().err
    assert err.count("was computed by other tfm source code (prov_code_hash 000000000000") == 1   # once
    assert "2 runs were computed by other tfm source code" in err


def test_the_resume_hint_of_a_dask_campaign_keeps_its_scheduler(tmp_path):
    """Followed as written, the hint resumed a Dask campaign locally, one run at a time."""
    from types import SimpleNamespace

    from tfm.campaign.runner import _again

    spec = load_spec(SMOKE)
    store = CampaignStore.for_spec(spec, tmp_path)
    client = SimpleNamespace(scheduler=SimpleNamespace(address="tcp://10.0.0.7:8786"))
    assert _again(spec, store, client) == (f"`tfm campaign run {spec.source} --results-dir {tmp_path} "
                                           "--scheduler tcp://10.0.0.7:8786`")
    assert "--scheduler" not in _again(spec, store)


def test_the_code_a_process_computes_with_is_read_once(monkeypatch):
    """A campaign's runs took the commit from the disk as each run started: after a commit
    made mid-campaign, runs computed by the code already loaded were labelled with the new
    commit (and a checkpoint with the new files' hash). Both are read once per process."""
    import tfm.results as results

    commit, code = results.loaded_commit(), results.code_hash()
    monkeypatch.setattr(results, "git_commit", lambda: "f" * 40)          # a commit meanwhile
    monkeypatch.setattr(results.Path, "rglob", lambda *a: iter(()))       # files edited meanwhile
    assert results.loaded_commit() == commit and results.code_hash() == code
    prov = results.provenance()
    assert (prov["git_commit"], prov["code_hash"]) == (commit, code)


def test_tables_follow_rewritten_runs_and_an_edited_file(tmp_path, monkeypatch):
    """The tables were rebuilt only when the set of done or failed ids changed: after
    --rerun-stale they kept the old runs' numbers, after a failed retry the old error, and
    after `allow` was removed from the file (not in the run id) the old p_allow."""
    sim_module = importlib.import_module("tfm.simulate")
    real = sim_module.simulate
    base = {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid", "max_indent": 0.05, "step": 5e-3}
    spec = spec_from_dict({"name": "cur", "base": {**base, "allow": "coarse"},
                           "sweep": {"alpha": [0.5, 0.75]}}, source="cur")
    victim = spec.runs[1].run_id

    def failing(message):
        def simulate(params, **kwargs):
            if params.run_id == victim:
                raise FloatingPointError(message)
            return real(params, **kwargs)
        return simulate

    monkeypatch.setattr(sim_module, "simulate", failing("first failure"))
    root = run_campaign(spec, quiet=True, results_dir=tmp_path)
    # other code: every stored run is stale, and its recomputation carries the new code
    monkeypatch.setattr("tfm.results._CODE_HASH", "1" * 64)
    monkeypatch.setattr("tfm.results._COMMIT", ["1" * 40])
    monkeypatch.setattr(sim_module, "simulate", failing("second failure"))
    run_campaign(spec, quiet=True, results_dir=tmp_path, rerun_stale=True)
    summary, _ = load_tables(root)
    assert summary["run_id"].tolist() == [spec.runs[0].run_id]
    assert summary["prov_git_commit"].tolist() == ["1" * 40] and summary["prov_code_hash"].tolist() == ["1" * 64]
    stored = read_metadata(CampaignStore(root).run_path(spec.runs[0].run_id))
    assert summary["r_wall_time"].iloc[0] == stored["summary"]["wall_time"]
    assert summary["prov_started_at"].iloc[0] == stored["provenance"]["started_at"]
    assert "second failure" in load_failures(root)["error"].iloc[0]

    edited = spec_from_dict({"name": "cur", "base": base, "sweep": {"alpha": [0.5, 0.75]}}, source="cur")
    assert edited.run_ids == spec.run_ids
    monkeypatch.setattr(sim_module, "simulate", real)
    run_campaign(edited, quiet=True, results_dir=tmp_path, retry_failed=False)
    assert load_tables(root)[0]["p_allow"].tolist() == [""]


@pytest.mark.parametrize("ci, quiet, bar, line", [("true", False, False, True), ("", False, True, True),
                                                 ("", True, False, False)])
def test_progress_bar_is_quiet_with_quiet_and_in_ci(tmp_path, monkeypatch, capsys, ci, quiet, bar, line):
    monkeypatch.setenv("CI", ci)
    tiny = spec_from_dict({"name": "tiny", "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                    "radius": 1.0, "max_indent": 0.05, "step": 5e-3}})
    run_campaign(tiny, quiet=quiet, results_dir=tmp_path)
    err = capsys.readouterr().err
    assert ("1/1" in err) == bar, err                       # the bar counts runs: "1/1 [...]"
    assert ("campaign tiny: 1 run done, 0 failed" in err) == line, err


def test_status_list_and_expand_commands(serial_run, tmp_path, capsys):
    results, _ = serial_run
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(results)]) == 0
    out = capsys.readouterr().out
    assert f"smoke: {N_SMOKE} runs: {N_SMOKE} done (0 flagged), 0 pending, 0 failed" in out
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path)]) == 0
    assert f"0 done (0 flagged), {N_SMOKE} pending" in capsys.readouterr().out
    assert tfm_main(["campaign", "list", "--dir", str(SMOKE.parent), "--results-dir", str(results)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(line.split()[:5] == ["smoke", str(N_SMOKE), "runs", str(N_SMOKE), "done"] for line in lines)
    # one line per campaign file (multi-line descriptions broke the table), counts in one column
    assert len(lines) == len(list(SMOKE.parent.glob("*.toml")))
    assert len({line.index(" runs ") for line in lines if "INVALID" not in line}) == 1
    assert tfm_main(["campaign", "expand", str(SMOKE)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[1] for line in lines] == load_spec(SMOKE).run_ids


def test_list_does_not_count_another_files_runs_as_a_campaigns_own(tmp_path, capsys):
    """Two files with one name: after a.toml ran, `list` showed b.toml with a.toml's done
    runs, while `status` and `run` refuse b.toml for that folder."""
    base = 'name = "same"\n[base]\nspacing = "1/16"\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.05\n' \
           'step = 5e-3\n[sweep]\n'
    (tmp_path / "a.toml").write_text(base + "radius = [1.0, 2.0]\n")
    (tmp_path / "b.toml").write_text(base + "radius = [1.0, 3.0]\n")
    run_campaign(tmp_path / "a.toml", quiet=True, results_dir=tmp_path / "res")
    capsys.readouterr()
    assert tfm_main(["campaign", "list", "--dir", str(tmp_path), "--results-dir", str(tmp_path / "res")]) == 0
    a, b = capsys.readouterr().out.splitlines()
    assert a.split()[:5] == ["a", "2", "runs", "2", "done"]
    assert b.split()[:3] == ["b", "2", "runs"] and "holds another campaign file's results" in b and "done" not in b
    # the folder follows the name inside the file, not the file's own name: both are said
    # (the list named each by its file alone, a user's hunt)
    assert f"(name 'same', results in {tmp_path / 'res' / 'same'})" in a


# ---- failures ------------------------------------------------------------------
def test_a_failing_run_is_recorded_and_the_others_finish(tmp_path, monkeypatch, capsys):
    sim_module = importlib.import_module("tfm.simulate")     # the package re-exports the function
    spec = load_spec(SMOKE)
    victim = spec.runs[2]
    real = sim_module.simulate

    def flaky(params, **kwargs):
        if params.run_id == victim.run_id:
            raise FloatingPointError("injected failure")
        return real(params, **kwargs)

    spec2 = spec_from_dict({"name": "flaky", "base": {k: v for k, v in spec.base.items()},
                            "sweep": spec.sweep, "zip": list(spec.zips)})
    monkeypatch.setattr(sim_module, "simulate", flaky)
    root = run_campaign(spec2, quiet=True, results_dir=tmp_path)
    summary, curves = load_tables(root)
    failures = load_failures(root)
    assert len(summary) == N_SMOKE - 1 and victim.run_id not in set(summary["run_id"])
    assert failures["run_id"].tolist() == [victim.run_id]
    assert failures["p_radius"].iloc[0] == victim.params.radius
    assert "FloatingPointError: injected failure" in failures["error"].iloc[0]
    assert "injected failure" in failures["traceback"].iloc[0] and "Traceback" in failures["traceback"].iloc[0]
    # status exits 1 while a run has failed
    assert tfm_main(["campaign", "status", "--results-dir", str(tmp_path), str(_toml_of(spec2, tmp_path))]) == 1
    assert "1 failed" in capsys.readouterr().out

    # the failure is retried on the next run, and disappears once the run succeeds
    monkeypatch.setattr(sim_module, "simulate", real)
    run_campaign(spec2, quiet=True, results_dir=tmp_path)
    summary, _ = load_tables(root)
    assert summary["run_id"].tolist() == spec.run_ids
    assert len(load_failures(root)) == 0


def _toml_of(spec, folder: Path) -> Path:
    """Write a spec back as a campaign file (for the CLI)."""
    lines = [f'name = "{spec.name}"', "[base]"]
    lines += [f"{k} = {v!r}" for k, v in spec.base.items()]
    lines += ["[sweep]"] + [f"{k} = {v!r}" for k, v in spec.sweep.items()]
    for group in spec.zips:
        lines += ["[[zip]]"] + [f"{k} = {v!r}" for k, v in group.items()]
    path = folder / f"{spec.name}.toml"
    path.write_text("\n".join(lines).replace("'", '"') + "\n")
    assert load_spec(path).run_ids == spec.run_ids
    return path


# ---- same results however the runs are executed ---------------------------------
@pytest.mark.parametrize("options, message", [
    (dict(jobs=4), "jobs: 4 applies to a local pool, not to a Dask cluster"),
    (dict(checkpoint_every=5.0), "checkpoint-every: Dask workers do not checkpoint"),
])
def test_options_a_dask_cluster_would_not_use_are_refused(tmp_path, options, message):
    """-j 4 and --checkpoint-every 5 with --scheduler were silently not used."""
    with pytest.raises(CampaignError, match=message):
        run_campaign(SMOKE, scheduler="tcp://127.0.0.1:9", results_dir=tmp_path, **options)
    assert not any(tmp_path.iterdir())        # refused before the campaign folder is made


def test_an_unreachable_scheduler_is_refused_before_the_folder_is_claimed(tmp_path, monkeypatch):
    """The campaign's folder and campaign.json were made, then the connection failed."""
    distributed = pytest.importorskip("distributed")

    def refused(address, timeout):        # what Client raises after its 30 s of retries
        raise OSError(f"Timed out trying to connect to {address} after {timeout}")

    monkeypatch.setattr(distributed, "Client", refused)
    with pytest.raises(CampaignError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        run_campaign(SMOKE, scheduler="tcp://127.0.0.1:9", results_dir=tmp_path)
    assert not any(tmp_path.iterdir())


def test_a_malformed_scheduler_address_is_refused_in_words(tmp_path):
    """An address without a port or with another scheme raised the ValueError of
    distributed as a traceback (a user's hunt); an unreachable one was refused in words."""
    pytest.importorskip("distributed")
    for address in ("notanaddress", "http://127.0.0.1:8786"):
        with pytest.raises(CampaignError, match=f"cannot reach the Dask scheduler at {address}"):
            run_campaign(SMOKE, scheduler=address, results_dir=tmp_path)
    assert not any(tmp_path.iterdir())


def test_checkpoint_every_and_no_checkpoints_are_one_or_the_other(tmp_path, capsys):
    """Given both, the last one won without a word (a user's hunt)."""
    from tfm.cli import main

    for argv in (["campaign", "run", str(SMOKE)], ["limit"]):
        with pytest.raises(SystemExit) as stop:
            main([*argv, "--results-dir", str(tmp_path / "r"), "--no-checkpoints", "--checkpoint-every", "5"])
        assert stop.value.code == 2
        assert "not allowed with argument" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_a_paper_report_folder_that_cannot_be_made_is_refused_before_the_runs(tmp_path, capsys):
    """tfm paper --out <a file> raised FileExistsError as a traceback (a user's hunt)."""
    from tfm.cli import main

    (tmp_path / "afile").write_text("")
    assert main(["paper", "--quick", "--out", str(tmp_path / "afile"), "--results-dir", str(tmp_path / "r")]) == 2
    assert "out: cannot make the report's folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_jobs_2_and_dask_match_jobs_1_bitwise(serial_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    results, _ = serial_run
    ref_summary, ref_curves = load_tables("smoke", results_dir=results)

    pool_root = run_campaign(SMOKE, jobs=2, quiet=True, results_dir=tmp_path / "pool")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                                  dashboard_address=None) as cluster:
        dask_root = run_campaign(SMOKE, scheduler=cluster.scheduler_address, quiet=True,
                                 results_dir=tmp_path / "dask")
    for root in (pool_root, dask_root):
        summary, curves = load_tables(root)
        assert_bitwise_equal(result_view(summary), result_view(ref_summary))
        assert_bitwise_equal(curves, ref_curves)
    # and they really ran with different thread counts (2 cores: 2 threads serial, 1 in the pool)
    pool_threads = set(load_tables(pool_root)[0]["prov_numba_threads"])
    assert set(ref_summary["prov_numba_threads"]) != pool_threads or os.cpu_count() == 1


def test_height_map_runs_on_dask_workers_that_cannot_read_the_map(tmp_path, monkeypatch):
    """Dask workers need no shared disk, but a height-map run read its map on the worker:
    it failed there (no such file) after passing validation on the client. The client now
    sends the heights it read, and the worker checks their hash against the run's."""
    import threading

    import tfm.surfaces

    distributed = pytest.importorskip("distributed")
    x = (np.arange(65) - 32) / 64
    np.save(tmp_path / "bowl.npy", (x[:, None] ** 2 + x[None, :] ** 2) / 2)   # a paraboloid, R = 1
    path = tmp_path / "bowl.toml"
    path.write_text(f'name = "bowl"\n[base]\nspacing = "1/32"\nshape = "height_map"\n'
                    f'height_map = "{tmp_path / "bowl.npy"}"\nmap_pixel_size = "1/64"\nk_th = 0.02\n'
                    'max_indent = 0.05\nstep = 2.5e-3\n')   # a ~ 7 spacings: a meaningful run
    (run,) = load_spec(path).runs
    reference = tfm.simulate(run.params)

    real_path = tfm.surfaces.Path

    def elsewhere(*args):                 # a worker thread looks at a disk without the map
        p = real_path(*args)
        return p if threading.current_thread() is threading.main_thread() else real_path("/nonexistent", p.name)

    monkeypatch.setattr(tfm.surfaces, "Path", elsewhere)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  dashboard_address=None) as cluster:
        root = run_campaign(path, scheduler=cluster.scheduler_address, quiet=True, results_dir=tmp_path)
    assert len(load_failures(root)) == 0, load_failures(root)["error"].tolist()
    _, curves = load_tables(root)
    assert_bitwise_equal(curves.drop(columns="run_id"), reference.curve)


def test_result_does_not_depend_on_thread_count():
    """A grid with more springs than one reduction block (4096), on 1 and 2 Numba threads."""
    import numba

    from tfm.simulate import simulate

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs 2 Numba threads")
    p = Params.from_dict(dict(spacing="1/128", shape="paraboloid", k_th=0.02, radius=1.0,
                              max_indent=0.05, step=0.01, allow="step"))   # 5 steps: enough here
    outs = []
    before = numba.get_num_threads()
    try:
        for n in (1, 2):
            numba.set_num_threads(n)
            outs.append(simulate(p))
    finally:
        numba.set_num_threads(before)
    a, b = outs
    assert a.summary["n_springs"] > 4096
    assert_bitwise_equal(a.curve, b.curve)
    assert {k: v for k, v in a.summary.items() if k != "wall_time"} == \
           {k: v for k, v in b.summary.items() if k != "wall_time"}


# ---- crash and resume ------------------------------------------------------------
def test_sigkill_then_resume_gives_the_uninterrupted_result(serial_run, tmp_path):
    results, _ = serial_run
    ref_summary, ref_curves = load_tables("smoke", results_dir=results)
    spec = load_spec(SMOKE)
    store = CampaignStore(tmp_path / "smoke")
    env = {**os.environ, "CI": "true"}
    proc = subprocess.Popen([sys.executable, "-m", "tfm.cli", "campaign", "run", str(SMOKE),
                             "--results-dir", str(tmp_path), "--quiet"],
                            cwd=REPO, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    try:
        while not any(store.runs_dir.glob("*.parquet")):
            assert proc.poll() is None, f"campaign exited early: {proc.stderr.read().decode()}"
            assert time.monotonic() < deadline, "no run finished within 2 minutes"
            time.sleep(0.005)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    _wait_until_group_is_gone(proc.pid)

    finished = sorted(store.runs_dir.glob("*.parquet"))
    assert 1 <= len(finished) < N_SMOKE, "the campaign was not interrupted in the middle"
    assert not store.table_path("summary").exists()                   # killed before the tables
    for path in finished:                                              # every visible run is whole
        assert read_metadata(path)["run_id"] == path.stem
        assert pq.read_table(path).num_rows == read_metadata(path)["summary"]["n_steps"]
    st = store.status(spec)
    assert len(st.done) == len(finished) and len(st.pending) == N_SMOKE - len(finished)

    # a half-written file, as a kill during a write would leave it
    partial = store.runs_dir / f".{spec.run_ids[-1]}.parquet.12345.tmp"
    partial.write_bytes(b"PAR1 truncated")
    run_campaign(SMOKE, quiet=True, results_dir=tmp_path)
    assert not partial.exists()
    assert not list(store.root.rglob("*.tmp"))
    assert sorted(p.stem for p in store.runs_dir.glob("*.parquet")) == sorted(spec.run_ids)
    summary, curves = load_tables(store.root)
    assert summary["run_id"].tolist() == spec.run_ids                  # each run exactly once
    assert_bitwise_equal(result_view(summary), result_view(ref_summary))
    assert_bitwise_equal(curves, ref_curves)


def _wait_until_group_is_gone(pgid: int, timeout: float = 30.0) -> None:
    """Children of the killed runner (e.g. a `git` it started) may take a moment to exit."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.01)
    raise AssertionError(f"process group {pgid} still alive {timeout} s after SIGKILL")


@pytest.mark.parametrize("sig, group", [(signal.SIGINT, False), (signal.SIGINT, True),
                                        (signal.SIGTERM, False)])
def test_an_interrupted_campaign_stores_what_finished_and_keeps_checkpoints(tmp_path, sig, group):
    """SIGINT to the campaign process alone waited for the runs in flight, then dropped
    their results, and their workers had removed the checkpoints: nothing was kept. Now
    the finished run is stored, the runs in flight stop at once and keep their checkpoints,
    and the command says how to resume (exit 128 + signal, no traceback); the same for
    Ctrl-C to the process group and for SIGTERM. Both runs in flight save their step in
    progress: the first worker to exit broke the pool, whose SIGTERM to the other was that
    worker's second signal, so it stopped at once, unsaved (half the stops lost a run's
    progress)."""
    path = tmp_path / "stop.toml"
    # one short run; two that would take minutes (no timed checkpoint: only the stop saves)
    path.write_text('name = "stop"\n[base]\nspacing = "1/32"\nk_th = 0.02\nshape = "paraboloid"\n'
                    'max_indent = 0.02\n[[zip]]\nalpha = [0.5, 0.7, 0.75]\nstep = [1e-3, 2e-7, 2e-7]\n')
    spec = load_spec(path)
    short, *long = spec.run_ids
    store = CampaignStore(tmp_path / "stop")
    proc = subprocess.Popen([sys.executable, "-m", "tfm", "campaign", "run", str(path), "--jobs", "2",
                             "--checkpoint-every", "1000", "--results-dir", str(tmp_path), "--quiet"],
                            cwd=REPO, env={**os.environ, "CI": "true", "PYTHONPATH": str(REPO)},
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not store.run_path(short).exists():
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the short run did not finish within 2 minutes"
            time.sleep(0.02)
        time.sleep(3.0)             # the second long run starts in the short run's worker
        os.killpg(proc.pid, sig) if group else proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)         # before: waited for the long runs
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = err.decode()
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err and f"interrupted by {signal.Signals(sig).name}" in err
    # with the results folder: without it the command would have started afresh in results/
    assert f"To resume, run `tfm campaign run {path} --results-dir {tmp_path}` again" in err
    st = store.status(spec)
    assert st.done == [short] and st.pending == long and st.failed == []
    assert load_tables(store.root)[0]["run_id"].tolist() == [short]
    for rid in long:
        meta = tfm_checkpoint.read_meta(store.checkpoint_path(rid))
        assert meta is not None and meta["run_id"] == rid and meta["steps"] > 0, (rid, err)
    assert err.count("tfm: saved the state after step") == 2, err
    assert not store.checkpoint_path(short).exists()


def test_a_second_runner_is_refused_while_one_holds_the_lock(tmp_path):
    store = CampaignStore(tmp_path / "smoke")
    with store.lock():
        with pytest.raises(CampaignError, match=f"pid {os.getpid()} .* is running this campaign"):
            with CampaignStore(store.root).lock(wait=0.1):
                pass
    with store.lock(wait=0.1):                  # released on exit
        pass


def test_load_tables_accepts_name_folder_or_file(serial_run):
    results, root = serial_run
    by_name = load_tables("smoke", results_dir=results)[0]
    for other in (root, SMOKE):
        assert load_tables(other, results_dir=results)[0]["run_id"].tolist() == by_name["run_id"].tolist()
    with pytest.raises(FileNotFoundError, match="run the campaign first"):
        load_tables("no-such-campaign", results_dir=results)


# ---- round trips ---------------------------------------------------------------------
def test_every_table_row_rebuilds_its_params_with_the_same_run_id(serial_run, capsys):
    results, root = serial_run
    summary, _ = load_tables("smoke", results_dir=results)
    for row in summary.to_dict("records"):           # NaN for None, NumPy scalars, "0.05" strings
        assert Params.from_row(row).run_id == row["run_id"]
    assert tfm_main(["campaign", "expand", str(SMOKE), "--json"]) == 0
    for line in capsys.readouterr().out.splitlines():
        record = json.loads(line)
        # from_row, whose docstring names these rows, read none of their bare names and
        # gave the default run, silently (a user's hunt)
        assert Params.from_row(record).run_id == record["run_id"]
        run_id = record.pop("run_id")
        record.pop("index")
        assert Params.from_dict(record).run_id == run_id
    # a row short of a parameter's column rebuilt another run at that parameter's default
    row = dict(summary.iloc[0])
    del row["p_shape"]
    with pytest.raises(tfm.ParameterError, match=f"its run_id is {row['run_id']}, but its parameters make run "
                                             r"\w+; the row has no column p_shape"):
        Params.from_row(row)


# ---- guards and sizes at expansion -------------------------------------------------------
@pytest.mark.parametrize("extra, expected", [
    ("spacing = '1/4'\nmax_indent = 0.01\nstep = 1e-3\n", ["run 0", "spacing: only", "--allow coarse"]),
    ("spacing = '1/32'\nmax_indent = 0.05\nstep = 5e-3\ntol = 1e-2\n", ["run 0", "tol: 0.01 is looser"]),
])
def test_a_meaningless_run_in_a_campaign_is_refused_at_expansion(tmp_path, extra, expected):
    path = _write(tmp_path, 'name = "g"\n[base]\nk_th = 0.02\nshape = "paraboloid"\n' + extra)
    with pytest.raises(CampaignError) as info:
        load_spec(path)
    assert str(info.value).startswith(str(path)) and all(e in str(info.value) for e in expected), info.value
    path.write_text(path.read_text() + "allow = 'coarse,tol'\n")
    assert len(load_spec(path).runs) == 1


def test_an_absurd_campaign_is_refused_with_its_count_before_it_expands(tmp_path, capsys, monkeypatch):
    million = {"name": "big", "base": {"k_th": 0.02, "shape": "paraboloid", "spacing": "1/32"},
               "sweep": {"radius": list(range(1, 101)), "alpha": [i / 100 for i in range(100)],
                         "step": [1e-4 * (i + 1) for i in range(100)]}}

    def expanded(*args):
        raise AssertionError("expanded")

    with monkeypatch.context() as m:
        m.setattr("tfm.campaign.spec._expand", expanded)      # counted, not expanded
        with pytest.raises(CampaignError, match=r"expands to 1,000,000 runs, more than max_runs = 10,000.*"
                                                r"max_runs = 1000000.*--max-runs 1000000"):
            spec_from_dict(million)
    path = _write(tmp_path, BASE.replace("[base]", "max_runs = 3\n[base]") + "[sweep]\nalpha = [0.5, 0.6, 0.7, 0.75]\n")
    assert tfm_main(["campaign", "expand", str(path)]) == 2
    assert "expands to 4 runs, more than max_runs = 3" in capsys.readouterr().err
    assert tfm_main(["campaign", "expand", str(path), "--max-runs", "4"]) == 0
    with pytest.raises(CampaignError, match="max_runs: expected a whole number"):
        spec_from_dict({"name": "x", "max_runs": "lots"})


def test_a_confirmed_large_campaign_says_that_it_is_being_checked(tmp_path, capsys, monkeypatch):
    """A million confirmed runs took minutes to check, in silence."""
    monkeypatch.setattr("tfm.campaign.spec.DEFAULT_MAX_RUNS", 3)
    path = _write(tmp_path, BASE + "[sweep]\nalpha = [0.5, 0.6, 0.7, 0.75]\n")
    assert tfm_main(["campaign", "expand", str(path), "--max-runs", "4"]) == 0
    assert f"tfm: note: {path}: checking the parameters of 4 runs" in capsys.readouterr().err
    path = _write(tmp_path, BASE + "[sweep]\nalpha = [0.5, 0.6, 0.7]\n")
    assert tfm_main(["campaign", "expand", str(path)]) == 0
    assert "note" not in capsys.readouterr().err


def test_a_campaign_that_cannot_fit_is_refused_before_any_run(tmp_path, monkeypatch):
    monkeypatch.setattr("tfm.guards.available_memory", lambda: 100 * 2 ** 20)
    with pytest.raises(CampaignError, match=r"needs about .* GiB for 2 at once, but 0.10 GiB is available"):
        run_campaign(SMOKE, jobs=2, quiet=True, results_dir=tmp_path)
    # no folder either: its campaign.json claimed the name for a file that ran nothing, and
    # refused another file of that name (a user's hunt)
    assert not (tmp_path / "smoke").exists()


def test_a_refusal_leaves_a_folder_that_was_there_as_it_was(tmp_path, monkeypatch):
    (tmp_path / "smoke").mkdir()
    (tmp_path / "smoke" / "notes.txt").write_text("mine")
    monkeypatch.setattr("tfm.guards.available_memory", lambda: 100 * 2 ** 20)
    with pytest.raises(CampaignError, match="needs about"):
        run_campaign(SMOKE, jobs=2, quiet=True, results_dir=tmp_path)
    assert not (tmp_path / "smoke" / "campaign.json").exists()
    assert (tmp_path / "smoke" / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("table", ["summary", "curves", "failures"])
def test_tables_that_no_campaign_wrote_are_not_replaced(tmp_path, table, capsys):
    """A summary.parquet of the user's own, in the folder a campaign's name points to, was
    overwritten without a word (a user's hunt)."""
    folder = tmp_path / "smoke"
    folder.mkdir()
    mine = folder / f"{table}.parquet"
    pd.DataFrame({"x": [1.0, 2.0]}).to_parquet(mine)
    before = mine.read_bytes()
    with pytest.raises(CampaignError, match=rf"{table}.parquet is not a table of a tfm campaign"):
        run_campaign(SMOKE, quiet=True, results_dir=tmp_path)
    assert mine.read_bytes() == before and not (folder / "campaign.json").exists()
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path)]) == 2
    assert "is not a table of a tfm campaign" in capsys.readouterr().err


# ---- one results folder per campaign file -------------------------------------------------
TINY = 'name = "dup"\n[base]\nspacing = "1/16"\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.05\nstep = 5e-3\n'


def test_another_file_with_the_same_name_is_refused(tmp_path, capsys):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first, second = tmp_path / "a" / "dup.toml", tmp_path / "b" / "dup.toml"
    first.write_text(TINY + "alpha = 0.5\n")
    second.write_text(TINY + "alpha = 0.75\n")
    res = str(tmp_path / "res")
    assert tfm_main(["campaign", "run", str(first), "--results-dir", res, "-q"]) == 0
    record = json.loads((tmp_path / "res" / "dup" / "campaign.json").read_text())
    assert record["origin"] == str(first.resolve()) and record["sha256"] == load_spec(first).digest
    before = pd.read_parquet(tmp_path / "res" / "dup" / "summary.parquet")
    assert tfm_main(["campaign", "run", str(second), "--results-dir", res, "-q"]) == 2
    err = capsys.readouterr().err
    assert "holds the results of campaign" in err and str(first) in err and "same name 'dup'" in err
    assert tfm_main(["campaign", "status", str(second), "--results-dir", res]) == 2
    assert pd.read_parquet(tmp_path / "res" / "dup" / "summary.parquet").equals(before)   # untouched

    # the same file, edited, resumes; a copy of it elsewhere (same content) is the same campaign
    first.write_text(TINY + "[sweep]\nalpha = [0.5, 0.6]\n")
    assert tfm_main(["campaign", "run", str(first), "--results-dir", res, "-q"]) == 0
    second.write_text("# a copy\n" + first.read_text())
    assert tfm_main(["campaign", "status", str(second), "--results-dir", res]) == 0
    assert "2 done" in capsys.readouterr().out

    # the file moved and then edited cannot be told from another campaign; the message
    # says how it takes over the results, and that way works
    moved = tmp_path / "b" / "moved" / "dup.toml"
    moved.parent.mkdir()
    first.rename(moved)
    moved.write_text(moved.read_text().replace("[0.5, 0.6]", "[0.5, 0.6, 0.7]"))
    assert tfm_main(["campaign", "status", str(moved), "--results-dir", res]) == 2
    err = capsys.readouterr().err
    json_path = tmp_path / "res" / "dup" / "campaign.json"
    assert f"moved and edited, delete {json_path} and it takes over these results" in err
    json_path.unlink()
    assert tfm_main(["campaign", "status", str(moved), "--results-dir", res]) == 0
    assert "3 runs: 2 done" in capsys.readouterr().out


# ---- a pool that survives a dead worker ------------------------------------------------------
def test_a_killed_worker_fails_only_its_own_run(tmp_path):
    """SIGKILL one pool worker mid-run (as the out-of-memory killer would): that run is
    recorded as failed with the cause, the pool is rebuilt, every other run finishes."""
    psutil = pytest.importorskip("psutil")
    path = tmp_path / "pool.toml"
    # 1/256: a run takes 2-4 s on a worker's one thread, far longer than a worker needs to
    # take its next run, so a worker killed a moment after a run finished is mid-run, not
    # idle (at 1/128, 0.4 s a run, the pool could finish before the kill).
    path.write_text('name = "pool"\n[base]\nspacing = "1/256"\nk_th = 0.02\nshape = "paraboloid"\n'
                    'max_indent = 0.05\nstep = 2.5e-4\n[sweep]\nalpha = [0.5, 0.6, 0.7, 0.75]\n')
    store = CampaignStore(tmp_path / "pool")
    proc = subprocess.Popen([sys.executable, "-m", "tfm", "campaign", "run", str(path), "--jobs", "2",
                             "--results-dir", str(tmp_path), "--quiet"],
                            cwd=REPO, env={**os.environ, "CI": "true", "PYTHONPATH": str(REPO)},
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 180
    killed = None
    try:
        while killed is None:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "no run finished within 3 minutes"
            if any(store.runs_dir.glob("*.parquet")):         # workers warm, runs in flight
                workers = [c for c in psutil.Process(proc.pid).children()
                           if "spawn_main" in " ".join(c.cmdline())]
                if len(workers) == 2:
                    time.sleep(0.2)                               # both past taking a run
                    killed = workers[0].pid
                    os.kill(killed, signal.SIGKILL)
            time.sleep(0.01)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, err.decode()
    summary, _ = load_tables(store.root)
    failures = load_failures(store.root)
    assert len(failures) == 1 and len(summary) == 3, (failures, err.decode())
    assert f"pid {killed}" in failures["error"].iloc[0] and "SIGKILL" in failures["error"].iloc[0]
    assert set(summary["run_id"]) | set(failures["run_id"]) == set(load_spec(path).run_ids)
    assert tfm_main(["campaign", "status", str(path), "--results-dir", str(tmp_path)]) == 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
def test_killing_the_campaign_stops_its_workers(tmp_path):
    """SIGKILL to `tfm campaign run --jobs 2` while both workers compute: the workers stop
    with it (before: they computed on as orphans until their run ended). SIGTERM, which
    the campaign handles itself, is in test_an_interrupted_campaign_stores_what_finished..."""
    psutil = pytest.importorskip("psutil")
    path = tmp_path / "orphans.toml"
    # 1/256 runs take seconds each, so a worker still alive 3 s after its parent died
    # would be one computing on as an orphan
    path.write_text('name = "orphans"\n[base]\nspacing = "1/256"\nk_th = 0.02\nshape = "paraboloid"\n'
                    'max_indent = 0.05\nstep = 2.5e-4\n[sweep]\nalpha = [0.5, 0.6, 0.7, 0.8]\n')
    proc = subprocess.Popen([sys.executable, "-m", "tfm", "campaign", "run", str(path), "--jobs", "2",
                             "--results-dir", str(tmp_path), "--quiet"],
                            cwd=REPO, env={**os.environ, "CI": "true", "PYTHONPATH": str(REPO)},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 180
    try:
        while True:                      # until both workers have computed for a while
            assert proc.poll() is None and time.monotonic() < deadline
            try:
                workers = [c for c in psutil.Process(proc.pid).children()
                           if "spawn_main" in " ".join(c.cmdline())]
                if len(workers) == 2 and all(w.cpu_times().user > 1.0 for w in workers):
                    break
            except psutil.NoSuchProcess:     # a child listed a moment ago has ended: look again
                pass
            time.sleep(0.05)
        proc.kill()
        proc.wait(timeout=30)
        gone, alive = psutil.wait_procs(workers, timeout=3)
    finally:
        if proc.poll() is None:
            proc.kill()
    for w in alive:
        w.kill()
    assert not alive, f"{len(alive)} workers outlived the campaign"


def test_the_pool_blames_the_run_whose_worker_died_and_finishes_the_rest(capsys):
    """In process: one run kills its own worker mid-run; it fails with the cause, the
    others (in flight on the other worker, or not yet started) finish in a rebuilt pool.
    The parent says so: the other worker's "stopping ... to save the run's state" lines
    read as if the campaign were stopping (a user's hunt)."""
    from killers import KillsItsWorker

    from tfm.campaign.runner import _run_pool
    from tfm.campaign.spec import Run

    good = load_spec(SMOKE).runs[:2]
    killer = Run(index=9, params=KillsItsWorker())
    outcomes = {run.run_id: outcome for run, outcome in _run_pool([killer, *good], jobs=2)}
    assert set(outcomes) == {killer.run_id, *(r.run_id for r in good)}
    assert "WorkerDied" in outcomes[killer.run_id].error and "was killed by SIGKILL" in outcomes[killer.run_id].error
    assert f"tfm: the worker running {killer.run_id} (pid " in capsys.readouterr().err
    for run in good:
        assert outcomes[run.run_id].result is not None, outcomes[run.run_id].error
        assert outcomes[run.run_id].result.params.run_id == run.run_id


@pytest.mark.parametrize("results_dir", ["/proc/tfm-results", "{tmp}/file/sub"])
def test_an_unwritable_results_folder_is_refused_before_any_run(tmp_path, capsys, results_dir):
    (tmp_path / "file").write_text("not a folder")
    results_dir = results_dir.format(tmp=tmp_path)
    assert tfm_main(["campaign", "run", str(SMOKE), "--results-dir", results_dir, "-q"]) == 2
    assert "results-dir: cannot write the campaign folder" in capsys.readouterr().err


def test_a_campaigns_parameter_warnings_name_the_run(tmp_path):
    """They printed as Python warnings ("spec.py:220: ParameterWarning: ... params =
    Params.from_dict(values, where=label)") without saying which run."""
    path = tmp_path / "zw.toml"
    path.write_text('name = "zw"\n[base]\nspacing = "1/32"\nshape = "paraboloid"\nmax_indent = 0.05\n'
                    'step = 1e-3\nalpha = 0.5\n[sweep]\nk_th = [0.0, 0.02]\n')
    proc = subprocess.run([sys.executable, "-m", "tfm", "campaign", "expand", str(path)], cwd=REPO,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0
    assert proc.stderr == (f"tfm: warning: {path}: run 0 (k_th=0.0): alpha: given but has no effect here: "
                           "every threshold is zero (no adhesion)\n")


def test_a_results_folder_in_a_missing_folder_is_refused(tmp_path, capsys):
    """A mistyped --results-dir made a whole new tree of folders and started the campaign
    afresh there; a folder inside an existing one is still made."""
    assert tfm_main(["campaign", "run", str(SMOKE), "--results-dir", str(tmp_path / "typo" / "res"), "-q"]) == 2
    assert "the folder that would hold" in capsys.readouterr().err and not (tmp_path / "typo").exists()


def test_a_capped_auto_preload_is_said_before_a_campaign_runs(tmp_path, capsys):
    spec = spec_from_dict({"name": "capped", "base": {"spacing": "1/64", "k_th": 0.05, "shape": "paraboloid",
                                                      "radius": 0.05, "step": 1e-3}})
    assert spec.runs[0].notes and "auto preload capped at 0.5 R" in spec.runs[0].notes[0]
    root = run_campaign(spec, results_dir=tmp_path)
    err = capsys.readouterr().err
    assert err.index("auto preload capped") < err.index("campaign capped: 1 run done")
    assert load_tables(root)[0]["status"].tolist() == ["flagged"]
    run_campaign(spec, results_dir=tmp_path / "quiet", quiet=True)   # a warning stays with -q (its help says so)
    assert "auto preload capped" in capsys.readouterr().err


def test_where_computes_only_the_selected_runs_and_resumes_the_rest(tmp_path, capsys):
    """--where KEY=VALUE: only matching runs are computed (values read as in the file, so
    a fraction matches its number); the tables hold what is stored; a later plain run
    finishes the rest. Bad selections fail before anything runs, naming what exists."""
    text = ('name = "part"\n[base]\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.025\n'
            '[sweep]\nalpha = [0.5, 0.75]\nspacing = ["1/16", "1/20"]\n')
    path = _write(tmp_path, text)
    res = tmp_path / "res"
    args = ["campaign", "run", str(path), "--results-dir", str(res), "-q"]
    capsys.readouterr()
    assert tfm_main(args[:-1] + ["--where", "alpha=0.75", "--where", "spacing=1/20"]) == 0
    # the runs not selected are neither done nor forgotten
    assert "1 run done, 0 failed, 0 already done, 3 not selected" in capsys.readouterr().err
    assert tfm_main(args[:-1] + ["--where", "alpha=0.75", "--where", "spacing=1/20"]) == 0
    assert "nothing to run, 1 of 4 runs already done, 3 not selected" in capsys.readouterr().err
    spec = load_spec(path)
    store = CampaignStore.for_spec(spec, res)
    done = store.status(spec).done
    assert len(done) == 1
    (run,) = [r for r in spec.runs if r.run_id in done]
    assert run.params.alpha == 0.75 and run.params.spacing == pytest.approx(1 / 20)
    summary, _ = load_tables(spec.name, results_dir=res)
    assert list(summary["run_id"]) == done
    assert tfm_main(args) == 0
    assert len(store.status(spec).done) == 4
    capsys.readouterr()
    for where, message in (("alpha=0.6", "its values of alpha: 0.5, 0.75"),
                           ("alpah=0.75", "did you mean 'alpha'"),
                           ("alpha", "expected KEY=VALUE")):
        assert tfm_main(args + ["--where", where]) == 2
        assert message in capsys.readouterr().err


def test_where_lists_the_values_a_user_can_type_back(tmp_path):
    """--where's refusal listed the first twelve values in text order and at 6 digits: of
    20 spacings the ones nearest the value asked for were hidden, and 0.0294118 (1/34),
    typed back, matched nothing."""
    from tfm.campaign import CampaignError, select_runs

    spacings = ", ".join(f'"1/{n}"' for n in range(16, 36))
    path = _write(tmp_path, 'name = "many"\n[base]\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.025\n'
                            f'allow = "coarse"\n[sweep]\nspacing = [{spacings}]\nalpha = [0.5, 0.75, 1.0]\n')
    spec = load_spec(path)
    with pytest.raises(CampaignError) as err:
        select_runs(spec, "spacing=0.0295")
    near = re.search(r"the 12 nearest to 0\.0295: (.*)$", str(err.value)).group(1).split(", ")
    assert "20 values" in str(err.value) and len(near) == 12
    nearest = sorted(sorted(range(16, 36), key=lambda n: abs(1 / n - 0.0295))[:12], reverse=True)
    # in numeric order, 1/35 .. 1/24, each as 1/N or its exact decimal (1/32 = 0.03125)
    assert [Fraction(v) for v in near] == [Fraction(1, n) for n in nearest]
    assert "1/35" in near and "0.03125" in near
    # each listed value, typed back, selects its runs
    for value in near:
        assert len(select_runs(spec, f"spacing={value}")) == 3
    with pytest.raises(CampaignError, match=r"its values of alpha: 0\.5, 0\.75, 1\.0$"):
        select_runs(spec, "alpha=2")


def test_run_campaign_takes_the_runs_select_runs_returns(tmp_path):
    """The docstring says only= takes select_runs' result; it raised 'unhashable type'.
    A single condition given as a string is one condition, not its characters."""
    from tfm.campaign import select_runs

    path = _write(tmp_path, 'name = "sel"\n[base]\nk_th = 0.02\nshape = "paraboloid"\nmax_indent = 0.025\n'
                            'spacing = "1/16"\n[sweep]\nalpha = [0.5, 0.75]\n')
    spec = load_spec(path)
    chosen = select_runs(spec, "alpha=0.75")
    assert [r.params.alpha for r in chosen] == [0.75]
    root = run_campaign(spec, only=chosen, quiet=True, results_dir=tmp_path / "res")
    assert load_tables(root)[0]["run_id"].tolist() == [chosen[0].run_id]


def test_every_column_of_the_tables_is_documented(serial_run):
    """README: docs/tables.md describes every column of every table (r_length_unit,
    r_force_unit and prov_resumed_at_step were missing)."""
    import re

    doc = (Path(__file__).resolve().parents[1] / "docs" / "tables.md").read_text()
    named = set(re.findall(r"`([a-z_0-9]+)`", doc))
    summary, curves = load_tables(serial_run[1])
    missing = [c for c in [*summary.columns, *curves.columns] if c not in named and not c.startswith("p_")]
    assert missing == []
    # and the other way: a documented provenance column is in every summary table
    # (prov_checkpoint_set_aside was only there when some checkpoint had been set aside)
    assert {c for c in named if c.startswith("prov_")} <= set(summary.columns)


def test_a_kernel_that_is_not_positive_definite_is_refused_before_anything_runs():
    """README: such a kernel "is refused" and every run is validated before anything runs;
    a campaign file expanded, then failed each run at its start (IllPosedKernel)."""
    base = {"spacing": "1/32", "k_th": 0.02, "shape": "paraboloid", "max_indent": 0.05, "step": 1e-3,
            "kernel": "neighbors"}
    # it named neither the file nor the run, unlike every other refusal (a user's hunt)
    with pytest.raises(CampaignError, match=r"^bad\.toml: run 0 \(neighbor_rings=1\): kernel: .*not positive definite"):
        spec_from_dict({"name": "bad", "base": base, "sweep": {"neighbor_rings": [1, 2]}}, source="bad.toml")
    with pytest.raises(tfm.ParameterError, match="not positive definite"):      # as tfm run says
        tfm.simulate(**{**base, "neighbor_rings": 1})


def test_a_list_in_base_points_to_sweep_and_zip():
    """[base] alpha = [0.5, 0.75] said "cannot read [0.5, 0.75] as a number", and a list of
    shapes "unknown value": neither said where lists go (a hunt)."""
    for key, value in (("alpha", [0.5, 0.75]), ("shape", ["sphere", "paraboloid"])):
        base = {"spacing": "1/32", "k_th": 0.02, "shape": "paraboloid", "max_indent": 0.05, key: value}
        with pytest.raises(CampaignError, match=rf"^bad\.toml: \[base\] {key} = .*: \[base\] holds one value per "
                                                r"parameter; a list of values goes in \[sweep\] .* or \[\[zip\]\]"):
            spec_from_dict({"name": "bad", "base": base}, source="bad.toml")


def _tiny(name):
    return spec_from_dict({"name": name, "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                  "max_indent": 0.05, "step": 5e-3},
                           "sweep": {"alpha": [0.5, 0.75]}}, source=name)


def test_status_says_when_the_tables_do_not_hold_the_stored_runs(tmp_path, capsys):
    """A campaign process killed after storing its last run, before it rebuilt the tables:
    status said "2 done", with no summary.parquet at all (a user's crash test)."""
    spec = _tiny("killed")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    store.table_path("summary").unlink()                       # as if killed before the rebuild
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "2 done" in out and "the tables (summary, curves, failures) are out of date: no readable summary table" in out
    # the command it gives keeps the results folder (without it: a fresh campaign in results/)
    assert f"`tfm campaign run {toml} --results-dir {tmp_path}` rebuilds them" in out
    # while a campaign process holds the folder, that is what status says (it said the
    # process had stopped)
    with store.lock():
        assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"pid {os.getpid()} on" in out and "is running this campaign now" in out and "out of date" not in out
    run_campaign(spec, quiet=True, results_dir=tmp_path)      # the same command rebuilds them
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    assert "out of date" not in capsys.readouterr().out and store.table_path("summary").exists()
    # a run file rewritten after the tables were
    store.run_path(spec.runs[0].run_id).touch()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    assert "out of date: run files have changed since they were written" in capsys.readouterr().out
    # a damaged run file: that run is pending again (it said "runs were stored after ...")
    store.run_path(spec.runs[0].run_id).write_bytes(b"cut short")
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    assert "out of date: they hold runs whose files are now gone or damaged" in capsys.readouterr().out


def test_status_says_when_the_campaign_file_was_edited(tmp_path, capsys):
    """A file edited in place after its campaign finished: status gave the reasons of a
    killed process or of a copy (a user's hunt)."""
    toml = _toml_of(_tiny("edited"), tmp_path)
    assert tfm_main(["campaign", "run", str(toml), "-q", "--results-dir", str(tmp_path)]) == 0
    toml.write_text(toml.read_text().replace("alpha = [0.5, 0.75]", "alpha = [0.5, 0.75, 0.625]"))
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 pending" in out and "out of date: the campaign file has changed since they were written" in out
    # every run pending after a base edit: the tables on disk still hold the old rows, and
    # status said nothing of them, only that those runs were "left out of the tables"
    toml.write_text(toml.read_text().replace("k_th = 0.02", "k_th = 0.03"))
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "0 done" in out and "3 pending" in out and "out of date: the campaign file has changed" in out
    assert "left out of the tables when they are next built" in out


def test_a_stop_signal_after_the_last_run_is_not_an_interruption(tmp_path, monkeypatch, capsys):
    """SIGTERM after every run was stored: the campaign said "interrupted, 0 runs did not
    finish" and a batch script saw exit 143 for a complete campaign."""
    import os
    import signal

    runner = importlib.import_module("tfm.campaign.runner")
    real = runner._consume

    def consume_then_signal(*a, **k):
        real(*a, **k)
        os.kill(os.getpid(), signal.SIGTERM)     # recorded by the campaign's handler

    monkeypatch.setattr(runner, "_consume", consume_then_signal)
    spec = _tiny("late")
    run_campaign(spec, quiet=True, results_dir=tmp_path)      # no CampaignInterrupted
    assert "the campaign is complete" in capsys.readouterr().err
    assert len(load_tables(spec, results_dir=tmp_path)[0]) == 2


def test_a_damaged_run_file_is_named_with_its_remedy(tmp_path, capsys):
    """A run file whose footer is intact but whose data is not (a machine crash, a bad copy)
    stopped every later `tfm campaign run` with a raw pyarrow traceback."""
    spec = _tiny("damaged")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    path = store.run_path(spec.runs[0].run_id)
    import pyarrow.parquet as pq

    chunk = pq.ParquetFile(path).metadata.row_group(0).column(4)     # the forces, say
    start, size = chunk.data_page_offset, chunk.total_compressed_size
    data = bytearray(path.read_bytes())
    data[start + size // 2:start + size] = bytes(size - size // 2)  # its data zeroed, the footer intact
    path.write_bytes(bytes(data))
    assert tfm_main(["campaign", "run", str(toml), "--results-dir", str(tmp_path), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: the stored run {spec.runs[0].run_id} cannot be read" in err and "delete it" in err
    path.unlink()
    assert tfm_main(["campaign", "run", str(toml), "--results-dir", str(tmp_path), "-q"]) == 0
    assert len(load_tables(spec, results_dir=tmp_path)[0]) == 2


def test_a_disk_that_refuses_a_write_stops_the_campaign_with_a_message(tmp_path, monkeypatch, capsys):
    """A full disk or a read-only folder ended the campaign with a raw traceback (a run
    file) or left no tables and no word that the runs were safe (the tables)."""
    spec = _tiny("disk")
    toml = _toml_of(spec, tmp_path)
    real = CampaignStore.write_run

    def full_after_one(self, run, *a, **k):
        if run.index == 1:
            raise OSError(28, "No space left on device", str(self.run_path(run.run_id)))
        return real(self, run, *a, **k)

    monkeypatch.setattr(CampaignStore, "write_run", full_after_one)
    with pytest.raises(CampaignError, match=r"cannot store run 1 \w+ in .*: No space left on device .*The runs "
                                            r"stored before it are kept.*run `tfm campaign run .*--results-dir"):
        run_campaign(load_spec(toml), quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    assert store.status(spec).done == [spec.runs[0].run_id]
    monkeypatch.setattr(CampaignStore, "write_run", real)

    def no_tables(self, *a, **k):
        raise OSError(27, "File too large")

    monkeypatch.setattr(CampaignStore, "write_tables", no_tables)
    with pytest.raises(CampaignError, match="cannot write the campaign's tables in .*: File too large. Every run "
                                            "is stored in"):
        run_campaign(load_spec(toml), quiet=True, results_dir=tmp_path)
    assert len(store.status(spec).done) == 2
    # exit status 1, as tfm run's for an output lost after computing (2 is bad input, before)
    assert tfm_main(["campaign", "run", str(toml), "--results-dir", str(tmp_path), "-q"]) == 1
    assert "cannot write the campaign's tables" in capsys.readouterr().err


def test_one_flipped_bit_in_a_run_file_is_found(tmp_path, capsys):
    """A flipped bit in a run file's data went unnoticed in 243 of 300 trials (Snappy pages
    have no checksum of their own), and the table held another number. The files carry
    page checksums now, verified on reading."""
    import pyarrow.parquet as pq

    spec = _tiny("flipped")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    path = store.run_path(spec.runs[0].run_id)
    chunk = pq.ParquetFile(path).metadata.row_group(0).column(4)     # the forces
    start, size = chunk.data_page_offset, chunk.total_compressed_size
    data = bytearray(path.read_bytes())
    data[start + size - 9] ^= 0x04                                   # one bit in the page's data
    path.write_bytes(bytes(data))
    store.table_path("summary").unlink()                             # the tables are rebuilt
    assert tfm_main(["campaign", "run", str(toml), "--results-dir", str(tmp_path), "-q"]) == 2
    assert f"{path}: the stored run {spec.runs[0].run_id} cannot be read" in capsys.readouterr().err


def test_runs_removed_from_the_file_are_reported_not_dropped_silently(tmp_path, capsys):
    """A value taken out of an edited campaign file: its stored run vanished from status and
    the tables without a word, and the file on disk was the only trace (a user's hunt)."""
    spec = _tiny("edited")
    toml = _toml_of(spec, tmp_path)
    args = ["--results-dir", str(tmp_path)]
    assert tfm_main(["campaign", "run", str(toml), "-q", *args]) == 0
    toml.write_text(toml.read_text().replace("alpha = [0.5, 0.75]", "alpha = [0.5]"))
    capsys.readouterr()
    assert tfm_main(["campaign", "run", str(toml), "-q", *args]) == 0     # said even with -q: rows leave the tables
    err = capsys.readouterr().err
    assert "1 stored run in" in err and "is not in the campaign file now" in err
    assert "or a height map's content changed" in err   # the other way a run id leaves the file
    store = CampaignStore.for_spec(load_spec(toml), tmp_path)
    assert len(store.load("summary")) == 1                    # the tables follow the file
    assert len(list(store.runs_dir.glob("*.parquet"))) == 2   # and the removed run is kept
    assert tfm_main(["campaign", "status", str(toml), *args]) == 0
    assert "1 stored run in" in capsys.readouterr().out
    toml.write_text(toml.read_text().replace("alpha = [0.5]", "alpha = [0.5, 0.75]"))
    assert tfm_main(["campaign", "status", str(toml), *args]) == 0
    out = capsys.readouterr().out
    assert "2 done" in out and "not in the campaign file" not in out


def test_a_dask_workers_own_thread_count_caps_its_share():
    """`NUMBA_NUM_THREADS=1 dask worker ...` on a shared 2-core host ran every run on 2
    threads (prov_numba_threads 2): the task wrote its share over the worker's own value."""
    import subprocess
    import sys

    from tfm.campaign.runner import capped_threads

    assert capped_threads(2, "1") == 1 and capped_threads(2, "4") == 2 and capped_threads(2, "") == 2
    code = "import tfm.campaign.runner as r; print(r.capped_threads(2))"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip() == "1"


def test_campaign_list_of_a_missing_folder_is_an_error(capsys):
    from tfm.cli import main

    assert main(["campaign", "list", "--dir", "no/such/folder"]) == 2
    assert "dir: no/such/folder is not a folder" in capsys.readouterr().err


def test_a_copy_of_a_campaign_with_its_times_is_current(tmp_path, capsys):
    """`cp -a` or `rsync -a` of a finished campaign: status called its tables stale (the
    digest held the run files' inodes, which every copy changes)."""
    import shutil

    spec = load_spec(SMOKE)
    root = run_campaign(spec, results_dir=tmp_path / "a", quiet=True)
    copy = tmp_path / "b" / root.name
    shutil.copytree(root, copy, copy_function=shutil.copy2)          # times kept, new inodes
    store = CampaignStore(copy)
    assert store.tables_current(spec)


def test_a_dask_campaign_without_workers_says_so(tmp_path, monkeypatch, capsys):
    """Every worker killed: the tasks waited for one, and the campaign with them, in silence
    (80 s at 2/6 in a user's try, until Ctrl-C). Now it says so, and Ctrl-C still stops it."""
    import threading

    import tfm.campaign.runner as runner

    distributed = pytest.importorskip("distributed")
    monkeypatch.setattr(runner, "NO_WORKERS_NOTE", 0.5)
    from tqdm.auto import tqdm
    written, write = [], tqdm.write
    monkeypatch.setattr(tqdm, "write", lambda s, *a, **k: (written.append(s), write(s, *a, **k)))
    with distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp", dashboard_address=None) as cluster:
        timer = threading.Timer(3.0, os.kill, (os.getpid(), signal.SIGINT))
        timer.start()
        try:
            with pytest.raises(KeyboardInterrupt):
                run_campaign(SMOKE, scheduler=cluster.scheduler_address, quiet=True, results_dir=tmp_path)
        finally:
            timer.cancel()
    assert "no Dask worker has been connected to tcp://" in capsys.readouterr().err
    # through tqdm.write, which puts it above a progress bar, not at the end of the bar's line
    assert any("no Dask worker" in w for w in written)


def test_a_base_key_that_applies_to_no_run_is_warned_about_once(tmp_path):
    """theta in [base] with the FFT operator: 'given but has no effect' came once per run
    (N lines for N runs). Now once, naming the runs; a warning of one run still names it."""
    path = tmp_path / "t.toml"
    path.write_text('name = "t"\n[base]\nspacing = "1/16"\nk_th = 0.02\nmax_indent = 0.01\nstep = 1e-3\n'
                    'theta = 0.5\nallow = "coarse"\n[sweep]\nalpha = [0.5, 0.75, 1.0]\n')
    with pytest.warns(ParameterWarning) as caught:
        load_spec(path)
    texts = [str(w.message) for w in caught if "theta" in str(w.message)]
    assert texts == [f"{path}: runs 0, 1, 2 (3 of 3): theta: given but has no effect; it applies only when "
                     "operator='tree' and kernel='boussinesq'"]


def test_a_smooth_reference_can_share_a_campaign_with_its_rough_runs(tmp_path):
    """rms_height swept through 0 with the roughness settings in [base] was refused
    ("short_cutoff: 0.125 has no effect here"), so the smooth reference needed a file of its
    own. The smooth run now takes the defaults, said and named; it is the very run a smooth
    file gives (same run id). A [base] key with an effect in no run is still refused."""
    base = ('name = "rz"\n[base]\nspacing = "1/32"\nk_th = 0.04\nshape = "paraboloid"\nextent = 0.5\n'
            'max_indent = 0.1\nstep = 2e-3\nshort_cutoff = "4/32"\nlong_cutoff = 0.25\nroughness_seed = 2\n')
    path = tmp_path / "rz.toml"
    path.write_text(base + "[sweep]\nrms_height = [0.0, 4e-3, 8e-3]\n")
    with pytest.warns(ParameterWarning) as caught:
        spec = load_spec(path)
    texts = [str(w.message) for w in caught]
    for name, value, default in (("short_cutoff", "'4/32'", "None"), ("long_cutoff", "0.25", "None"),
                                 ("roughness_seed", "2", "0")):
        assert f"{path}: run 0 (1 of 3): [base] {name} = {value} has no effect there (it applies only when the " \
               f"surface is rough (rms_slope or rms_height > 0)), so they run with its default {default}; " \
               "the other runs use it" in texts
    smooth = Params.from_dict(dict(spacing="1/32", k_th=0.04, shape="paraboloid", extent=0.5, max_indent=0.1,
                                   step=2e-3))
    assert spec.runs[0].params == smooth and spec.runs[0].run_id == smooth.run_id
    rough = spec.runs[1].params
    assert (rough.short_cutoff, rough.long_cutoff, rough.roughness_seed, rough.rms_height) == (0.125, 0.25, 2, 4e-3)
    path.write_text(base + "[sweep]\nrms_height = [0.0]\nalpha = [0.5, 0.75]\n")
    with pytest.raises(CampaignError, match=r"\[base\] short_cutoff: 0.125 has no effect here; .*; in every run"):
        load_spec(path)


def test_status_names_checkpoints_of_runs_no_longer_in_the_file(tmp_path, capsys):
    """A run removed from the campaign file while it had a checkpoint: the file stayed in
    checkpoints/ for good, and status never mentioned it."""
    root = run_campaign(SMOKE, quiet=True, results_dir=tmp_path)
    store = CampaignStore(root)
    store.checkpoints_dir.mkdir(exist_ok=True)
    (store.checkpoints_dir / "0123456789abcdef.npz").write_bytes(b"PK")
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"1 checkpoint in {store.checkpoints_dir} belongs to runs no longer in the file (0123456789abcdef): " \
           "they are kept" in out


def test_a_stopped_pool_worker_removes_its_temporary_snapshot_files(tmp_path):
    """Ctrl-C on a campaign with snapshots: the pool's SIGTERM killed the workers mid-run,
    and their snapshot files (the temporary one and the hidden .tmp being written, 4.9 MB
    each at 1/256) stayed in the temporary folder for an hour."""
    import subprocess
    import sys

    code = ("import os, signal, tempfile; tempfile.tempdir = os.environ['TMPDIR_TEST']\n"
            "from tfm.campaign.runner import _pool_init\n"
            "from tfm.snapshots import LIVE_TEMPORARIES, temporary_fields_path\n"
            "_pool_init(1)\n"
            "path = temporary_fields_path(); tmp = path.with_name('.' + path.name + '.1.tmp')\n"
            "tmp.write_bytes(b'half'); LIVE_TEMPORARIES.add(tmp)\n"
            "print(path, tmp, flush=True)\n"
            "os.kill(os.getpid(), signal.SIGTERM)\n"
            "import time; time.sleep(5); print('alive')\n")
    env = dict(os.environ, TMPDIR_TEST=str(tmp_path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == -signal.SIGTERM and "alive" not in proc.stdout
    assert proc.stdout.split() and not list(tmp_path.iterdir())


def test_a_campaign_whose_height_map_is_gone_says_why_it_needs_it(tmp_path, capsys):
    """`tfm campaign status` of a campaign whose map was moved said only "no such file",
    and a user could not see why a status needs the map at all."""
    path = tmp_path / "hm.toml"
    path.write_text('name = "hm"\n[base]\nspacing = "1/32"\nshape = "height_map"\nheight_map = "gone.npy"\n'
                    'map_pixel_size = "1/32"\nf_th = 0\nmax_indent = 0.01\nstep = 1e-3\n')
    assert tfm_main(["campaign", "status", str(path)]) == 2
    err = capsys.readouterr().err
    assert "height_map: no such file" in err and "a campaign needs its height maps to know its runs" in err


def test_campaign_list_exits_2_on_an_invalid_file_and_a_bom_is_named(tmp_path, capsys):
    """An invalid file was listed as INVALID with exit 0, and a file saved with a byte order
    mark was 'not valid TOML: Invalid statement (at line 1, column 1)' (a user's hunt)."""
    from tfm.cli import main

    good = SMOKE.read_text()
    (tmp_path / "good.toml").write_text(good)
    assert main(["campaign", "list", "--dir", str(tmp_path), "--results-dir", str(tmp_path)]) == 0
    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + good.replace('name = "smoke"', 'name = "bom"').encode())
    capsys.readouterr()
    assert main(["campaign", "list", "--dir", str(tmp_path), "--results-dir", str(tmp_path)]) == 2
    out = capsys.readouterr().out
    assert "bom" in out and "byte order mark (BOM)" in out and "good" in out


def test_a_file_where_a_campaign_folder_should_be_is_named_before_any_run(tmp_path):
    """A file named runs where the run files go: the campaign computed its first run, then
    stopped with "free space or fix the permissions" (a user's try)."""
    spec = _tiny("blocked")
    store = CampaignStore.for_spec(spec, tmp_path)
    store.root.mkdir()
    store.runs_dir.write_text("not a folder")
    with pytest.raises(CampaignError, match=r"results-dir: .*runs is a file, where the campaign keeps its "
                                            r"runs/ folder; move it away"):
        run_campaign(spec, quiet=True, results_dir=tmp_path)
    assert not store.checkpoints_dir.exists() and not store.table_path("summary").exists()


def test_status_of_a_results_dir_that_does_not_exist(tmp_path, capsys):
    """A mistyped --results-dir showed every run as pending, as if nothing had been computed."""
    spec = _tiny("elsewhere")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path / "res")
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path / "rse")]) == 2
    assert f"results-dir: {tmp_path / 'rse'} is not a folder" in capsys.readouterr().err
    assert tfm_main(["campaign", "list", "--dir", str(tmp_path), "--results-dir", str(tmp_path / "rse")]) == 2
    # an existing folder without this campaign: pending, and said why
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "2 pending" in out and f"nothing stored yet: {tmp_path / 'elsewhere'} does not exist" in out
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path / "res")]) == 0
    out = capsys.readouterr().out
    assert "2 done" in out and "nothing stored" not in out


def test_a_damaged_run_file_is_reported_then_computed_again(tmp_path, capsys):
    """A run file cut short (a disk error, a bad copy) was computed again without a word:
    status counted it pending like a run never started."""
    spec = _tiny("damaged")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    rid = spec.runs[1].run_id
    data, curve = store.run_path(rid).read_bytes(), pd.read_parquet(store.run_path(rid))
    store.run_path(rid).write_bytes(data[:len(data) // 2])
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 done" in out and "1 pending" in out
    assert (f"1 run file in {store.runs_dir} cannot be read as the run it is named after (damaged or cut "
            f"short? e.g. {rid}.parquet): that run is pending and computed again") in out
    run_campaign(spec, quiet=True, results_dir=tmp_path)       # said even with quiet
    assert "warning: campaign damaged: 1 run file" in capsys.readouterr().err
    assert store.status(spec).done == spec.run_ids
    assert_bitwise_equal(pd.read_parquet(store.run_path(rid)), curve)


def test_a_run_whose_snapshots_are_gone_or_damaged_is_computed_again(tmp_path, capsys):
    """A run stored with field snapshots counted as done when its snapshots file was
    deleted or truncated: status said "done", run "nothing to run", and only tfm show
    noticed (a hunt)."""
    from tfm.snapshots import Fields

    spec = spec_from_dict({"name": "snaps", "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                     "max_indent": 0.05, "step": 5e-3, "snapshots": "events"},
                           "sweep": {"alpha": [0.25, 0.5, 0.75]}}, source="snaps")
    toml = _toml_of(spec, tmp_path)
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    store = CampaignStore.for_spec(spec, tmp_path)
    cut, gone, kept = spec.run_ids
    steps = Fields(store.fields_path(cut)).steps.tolist()
    data = store.fields_path(cut).read_bytes()
    store.fields_path(cut).write_bytes(data[:2000])
    store.fields_path(gone).unlink()
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 done" in out and "2 pending" in out, out
    assert (f"2 stored runs in {store.runs_dir} lack the field snapshots they stored (e.g. {cut}.fields.nc: "
            "unreadable (damaged or cut short?)): those runs are pending and computed again with them") in out
    run_campaign(spec, quiet=True, results_dir=tmp_path)
    assert "warning: campaign snaps: 2 stored runs" in capsys.readouterr().err
    assert store.status(spec).done == spec.run_ids
    assert Fields(store.fields_path(cut)).steps.tolist() == steps and store.fields_path(gone).exists()


def test_status_of_a_limit_campaign_counts_its_kept_points(tmp_path, monkeypatch, capsys):
    """status said "60 pending" for limit_sphere, whose 60 runs all have a kept point in
    results/limit/points.csv (the runs are too large to keep): a user would have computed
    about ten hours again with `tfm campaign run` instead of `make limit`."""
    import csv

    monkeypatch.chdir(REPO)
    spec = load_spec(REPO / "campaigns" / "limit_sphere.toml")
    with open(REPO / "results" / "limit" / "points.csv", newline="") as fh:
        kept = {row["run_id"] for row in csv.DictReader(fh)} & set(spec.run_ids)
    assert kept
    assert tfm_main(["campaign", "status", "campaigns/limit_sphere.toml", "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (f"{len(kept)} pending runs have a kept point in results/limit/points.csv: `tfm limit` (make limit) "
            "fits those and computes only the rest") in out
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path)]) == 0
    assert "kept point" not in capsys.readouterr().out


def test_runs_left_out_are_named_as_the_caller_says(tmp_path, capsys):
    """tfm limit leaves out the runs that have a kept point: "0 of 60 runs already done,
    60 not selected" read as if nothing had been computed."""
    spec = _tiny("kept")
    run_campaign(spec, results_dir=tmp_path, only=[], left_out_as="with a kept point")
    assert "nothing to run, 0 of 2 runs already done, 2 with a kept point" in capsys.readouterr().err


def test_status_says_a_changed_height_map_left_the_tables_behind(tmp_path, capsys):
    """The map's content changed under an unchanged campaign file: the run files are all
    there, yet status called them "gone or damaged" (a user's hunt)."""
    x = (np.arange(33) - 16) / 32
    bowl = (x[:, None] ** 2 + x[None, :] ** 2) / 2
    np.save(tmp_path / "bowl.npy", bowl)
    toml = tmp_path / "bowl.toml"
    toml.write_text(f'name = "bowl"\n[base]\nspacing = "1/32"\nshape = "height_map"\n'
                    f'height_map = "{tmp_path / "bowl.npy"}"\nmap_pixel_size = "1/32"\nk_th = 0.02\nmax_indent = 0.05\n'
                    'step = 5e-3\n')
    run_campaign(toml, quiet=True, results_dir=tmp_path)
    np.save(tmp_path / "bowl.npy", 1.5 * bowl)                # another body, same file name
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "out of date: they hold runs the campaign file no longer expands to" in out
    assert "gone or damaged" not in out
    # run on the new content, then the old content put back: its runs are on disk and
    # current again, and the tables hold the new content's; that was called "stored after
    # they were written, by a campaign process that stopped" (another hunt)
    run_campaign(toml, quiet=True, results_dir=tmp_path)
    np.save(tmp_path / "bowl.npy", bowl)
    capsys.readouterr()
    assert tfm_main(["campaign", "status", str(toml), "--results-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "out of date: they hold runs the campaign file no longer expands to" in out
    assert "stopped before rebuilding" not in out
