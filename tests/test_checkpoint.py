"""Checkpoints: a run stopped mid-curve continues from its last saved step, and ends with
the curve of a run that was never stopped, bit for bit; a checkpoint that cannot serve is
refused before any computation, or set aside with a warning."""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tfm.checkpoint
import tfm.protocol
import tfm.results
from tfm import Params, simulate
from tfm.campaign import (CampaignError, CampaignStore, load_spec, load_tables, run_campaign,
                          spec_from_dict)
from tfm.checkpoint import CheckpointWarning
from tfm.params import ParameterError
from tfm.cli import main as tfm_main

# 20 loading steps and about as many unloading ones: a second or two.
REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "campaigns" / "smoke.toml"
P = Params(spacing=1 / 32, k_th=0.02, f_th=None, shape="paraboloid", max_indent=0.02, step=1e-3)
N_LOAD = 20


class Stop(Exception):
    """Stands for a crash: raised from the progress callback after a recorded step."""


def stop_after(steps: int):
    def progress(rec):
        if rec.step + 1 == steps:
            raise Stop
    return progress


@contextlib.contextmanager
def crash_after(steps: int):
    """A crash (RuntimeError) once ``steps`` steps have been recorded, in any run of this
    process: raised after the step is recorded and before its checkpoint is saved."""
    record, count = tfm.protocol._record, [0]

    def crashing(out, state, rec, observe):
        record(out, state, rec, observe)
        count[0] += 1
        if count[0] == steps:
            raise RuntimeError("simulated crash")

    tfm.protocol._record = crashing
    try:
        yield
    finally:
        tfm.protocol._record = record


def assert_same_run(a, b) -> None:
    """Same curve (every column; floats bit for bit) and same summary, but the wall time."""
    assert list(a.curve.columns) == list(b.curve.columns) and len(a.curve) == len(b.curve)
    for col in a.curve.columns:
        x, y = a.curve[col].to_numpy(), b.curve[col].to_numpy()
        if x.dtype.kind == "f":
            assert (x.view(np.uint64) == y.view(np.uint64)).all(), col
        else:
            assert (x == y).all(), col
    sa = {k: v for k, v in a.summary.items() if k != "wall_time"}
    sb = {k: v for k, v in b.summary.items() if k != "wall_time"}
    assert sa.keys() == sb.keys()
    for k in sa:
        assert sa[k] == sb[k] or (sa[k] != sa[k] and sb[k] != sb[k]), k    # NaN == NaN here


@pytest.fixture(scope="module")
def reference():
    return simulate(P)


def test_a_run_stopped_twice_ends_with_the_uninterrupted_curve(reference, tmp_path):
    """Stopped in the loading phase, resumed, stopped in the unloading phase, resumed: the
    saved states (every step, checkpoint_every=0) carry everything a later step reads."""
    assert len(reference.curve) > N_LOAD + 5
    path = tmp_path / "run.npz"
    with pytest.raises(Stop):
        simulate(P, progress=stop_after(7), checkpoint=path, checkpoint_every=0)
    # the 7th step raised before its save: the checkpoint holds 6 steps
    assert tfm.checkpoint.read_meta(path)["steps"] == 6
    with pytest.raises(Stop):
        simulate(P, progress=stop_after(N_LOAD + 4), checkpoint=path, checkpoint_every=0)
    meta = tfm.checkpoint.read_meta(path)
    assert meta["steps"] == N_LOAD + 3 and meta["phase"] == "unload"
    res = simulate(P, checkpoint=path, checkpoint_every=0)
    assert res.provenance["resumed_at_step"] == N_LOAD + 3
    assert not path.exists()              # a finished run leaves no checkpoint
    assert_same_run(res, reference)
    assert reference.provenance["resumed_at_step"] == 0


def signal_after(steps: int, sig=signal.SIGINT):
    """A stop signal to this process while the run computes, once ``steps`` steps are recorded."""
    def progress(rec):
        if rec.step + 1 == steps:
            os.kill(os.getpid(), sig)
    return progress


@pytest.mark.parametrize("at", [7, N_LOAD + 4, "last"])
def test_ctrl_c_saves_the_step_in_progress(reference, tmp_path, capsys, at):
    """Ctrl-C cost the work since the last periodic save (every 10 minutes by default).
    Now the step in progress ends, its state is saved, and then KeyboardInterrupt comes;
    during the last step the whole curve is kept, and continuing it computes nothing. The
    continued run is the uninterrupted one, bit for bit."""
    steps = len(reference.curve) if at == "last" else at
    path = tmp_path / "run.npz"
    with pytest.raises(KeyboardInterrupt):
        simulate(P, progress=signal_after(steps), checkpoint=path)      # no periodic save
    assert "stopping after the step in progress" in capsys.readouterr().err
    meta = tfm.checkpoint.read_meta(path)
    assert meta["steps"] == steps
    assert meta["phase"] == ("done" if at == "last" else "load" if steps <= N_LOAD else "unload")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler    # handler restored
    first = meta["started_at"]
    res = simulate(P, checkpoint=path)
    assert res.provenance["resumed_at_step"] == steps and not path.exists()
    assert_same_run(res, reference)
    # the run's start, not the resuming process's (it said when the run was resumed)
    assert res.provenance["started_at"] == first and first is not None
    assert res.provenance["numba_threads"] >= 1       # a single run records its threads too


def test_sigterm_saves_the_step_in_progress_then_ends_the_process(tmp_path):
    """SIGTERM (a cluster's time limit, `kill`) killed a run at once. Now the process ends
    the same way, by SIGTERM, after saving the step in progress."""
    path = tmp_path / "run.npz"
    code = ("import os, signal; from tfm import Params, simulate\n"
            f"P = Params(spacing=1/32, k_th=0.02, f_th=None, shape='paraboloid', max_indent=0.02, step=1e-3)\n"
            "def progress(rec):\n"
            "    if rec.step == 4: os.kill(os.getpid(), signal.SIGTERM)\n"
            f"simulate(P, progress=progress, checkpoint={str(path)!r})\n"
            "print('not stopped')\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == -signal.SIGTERM, proc.stderr
    assert "not stopped" not in proc.stdout and "SIGTERM: stopping after the step in progress" in proc.stderr
    assert tfm.checkpoint.read_meta(path)["steps"] == 5


def test_a_checkpoint_of_another_run_or_engine_is_set_aside(reference, tmp_path, monkeypatch):
    """Another run's saved state, or a file that is no checkpoint, at the path given was
    set aside with a warning, then overwritten and deleted: a user's own results.npz was
    lost. Now it is refused and left alone (as `tfm run` does without --overwrite) unless
    replace_checkpoint=True; this run's state by another engine is still set aside."""
    path = tmp_path / "run.npz"
    other = P.replace(alpha=0.5)
    with pytest.raises(Stop):
        simulate(other, progress=stop_after(5), checkpoint=path, checkpoint_every=0)
    saved = path.read_bytes()
    with pytest.raises(ParameterError, match=f"holds the saved state of another run \\({other.run_id}\\)"):
        simulate(P, checkpoint=path)
    assert path.read_bytes() == saved
    with pytest.warns(CheckpointWarning, match=f"belongs to run '{other.run_id}'.*starts afresh"):
        res = simulate(P, checkpoint=path, replace_checkpoint=True)
    assert res.provenance["resumed_at_step"] == 0
    assert_same_run(res, reference)

    with pytest.raises(Stop):
        simulate(P, progress=stop_after(5), checkpoint=path, checkpoint_every=0)
    monkeypatch.setattr(tfm.results, "_CODE_HASH", "another engine")
    with pytest.warns(CheckpointWarning, match="another version of tfm's source"):
        res = simulate(P, checkpoint=path)
    assert res.provenance["resumed_at_step"] == 0

    path.write_bytes(b"not a checkpoint")
    with pytest.raises(ParameterError, match="holds a file that is not a readable checkpoint; it is left alone"):
        simulate(P, checkpoint=path)
    assert path.read_bytes() == b"not a checkpoint"
    with pytest.warns(CheckpointWarning, match="cannot be read"):
        simulate(P, checkpoint=path, replace_checkpoint=True)
    with pytest.raises(ParameterError, match="keep_checkpoint: applies only with a checkpoint path"):
        simulate(P, keep_checkpoint=True)


def test_checkpoint_arguments_of_the_wrong_kind_are_refused_by_name(tmp_path):
    """A .npy array saved under .npz gave "TypeError: 'numpy.ndarray' object does not
    support the context manager protocol"; checkpoint=True a TypeError from pathlib; a folder
    was "a file that is not a readable checkpoint"; keep_checkpoint="no" kept the file (a
    true string); checkpoint_every="10" "must be >= 0 seconds"."""
    array = tmp_path / "array.npz"
    with open(array, "wb") as fh:
        np.save(fh, np.arange(3))
    with pytest.raises(ParameterError, match="holds a file that is not a readable checkpoint; it is left alone"):
        simulate(P, checkpoint=array)
    assert tfm.checkpoint.read_meta(array) is None
    for kw, message in ((dict(checkpoint=True), "checkpoint: expected a file path .*got True"),
                        (dict(checkpoint=tmp_path), f"checkpoint: {tmp_path} is a folder; give a file path"),
                        (dict(checkpoint=tmp_path / "c.npz", keep_checkpoint="no"),
                         "keep_checkpoint: expected True or False, got 'no'"),
                        (dict(checkpoint=tmp_path / "c.npz", checkpoint_every="10"),
                         "checkpoint_every: expected a number of seconds >= 0, got '10'")):
        with pytest.raises(ParameterError, match=message):
            simulate(P, **kw)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["array.npz"]


def test_a_checkpoint_that_cannot_be_saved_names_its_file(tmp_path, monkeypatch):
    """On a full disk a campaign's run failed with 'OSError: [Errno 27] File too large',
    with no word that it was the checkpoint, nor which. The warning that replaced the
    failure (below) names it."""
    def full(*a, **k):
        raise OSError(27, "File too large")

    monkeypatch.setattr(np, "savez", full)
    path = tmp_path / "run.npz"
    with pytest.warns(CheckpointWarning, match=f"cannot save the checkpoint {path}: File too large"):
        simulate(P, checkpoint=path, checkpoint_every=0)
    assert list(tmp_path.iterdir()) == []                 # no temporary file left either


def test_a_damaged_checkpoint_is_set_aside_not_a_failure_for_good(tmp_path, capsys):
    """A truncated checkpoint (or one with a flipped bit) raised BadZipFile: its run
    failed on every retry and `tfm campaign status` crashed. It is now reported as
    unreadable, and the run starts afresh, warned, with the same result."""
    spec = load_spec(SMOKE)
    reference = run_campaign(spec, results_dir=tmp_path / "ref", quiet=True)
    store = CampaignStore.for_spec(spec, tmp_path / "res")
    rid = spec.runs[0].run_id
    store.checkpoint_path(rid).parent.mkdir(parents=True)
    store.checkpoint_path(rid).write_bytes(b"PK\x03\x04" + bytes(200))       # a cut-off archive
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path / "res"), "-v"]) == 0
    out = capsys.readouterr().out
    assert "cannot be read (damaged?): the run will start afresh" in out
    # the count said it would continue from it (a user's hunt)
    assert "1 unfinished run has a checkpoint that cannot be continued from (see below): it starts afresh" in out
    assert "continues from it" not in out
    root = run_campaign(spec, results_dir=tmp_path / "res", quiet=True)
    assert "cannot be read (BadZipFile" in capsys.readouterr().err          # a warning line, even with quiet
    summary, curves = load_tables(root)
    ref_summary, ref_curves = load_tables(reference)
    pd.testing.assert_frame_equal(curves, ref_curves)
    row = summary.set_index("run_id").loc[rid]
    assert "cannot be read" in row["prov_checkpoint_set_aside"] and row["prov_resumed_at_step"] == 0


@pytest.mark.parametrize("changes, options, expected", [
    ({"control": "force", "max_load": 0.01, "load_step": 1e-3, "max_indent": "auto"}, {}, "only displacement-controlled"),
    ({"snapshots": 5}, {}, "field snapshots"),
    ({}, {"checkpoint_every": -1.0}, "checkpoint_every: must be >= 0"),
])
def test_a_checkpoint_that_cannot_serve_is_refused_before_any_computation(tmp_path, monkeypatch,
                                                                         changes, options, expected):
    def no_work(*args, **kwargs):
        raise AssertionError("computed")

    monkeypatch.setattr(tfm.protocol, "run", no_work)
    with pytest.raises(ValueError, match=expected):
        simulate(P.replace(**changes), checkpoint=tmp_path / "run.npz", **options)
    with pytest.raises(CampaignError, match="checkpoint-every"):
        run_campaign(load_spec(SMOKE), results_dir=tmp_path, checkpoint_every=-1)


def test_a_campaign_run_that_crashed_continues_from_its_checkpoint(tmp_path, capsys, monkeypatch):
    """The first run of the smoke campaign crashes after 10 steps (a failure is recorded,
    its checkpoint stays); the next `campaign run` continues it from step 9 and the tables
    equal those of an uninterrupted campaign."""
    spec = load_spec(SMOKE)
    clean = run_campaign(spec, quiet=True, results_dir=tmp_path / "clean")

    with crash_after(10):
        root = run_campaign(spec, quiet=True, results_dir=tmp_path / "crashed", checkpoint_every=0)
    store = CampaignStore(root)
    first = spec.runs[0].run_id
    assert store.status(spec).failed == [first]
    assert store.checkpoint_path(first).exists()
    assert tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path / "crashed")]) == 1
    assert "1 unfinished run has a checkpoint: it continues from it" in capsys.readouterr().out
    with monkeypatch.context() as m:              # as after an edit of tfm's source
        m.setattr("tfm.checkpoint.code_hash", lambda: "another")
        tfm_main(["campaign", "status", str(SMOKE), "--results-dir", str(tmp_path / "crashed"), "-v"])
        out = capsys.readouterr().out
    assert "was written by another version of tfm's source" in out and "it starts afresh" in out
    assert "continues from it" not in out

    # resumed with --no-checkpoints (checkpoint_every=None): the saved state still serves
    # (it was deleted unused and the run computed again from its first step)
    run_campaign(spec, quiet=True, results_dir=tmp_path / "crashed", checkpoint_every=None)
    assert not any(store.checkpoints_dir.iterdir())
    summary, curves = load_tables(root)
    ref_summary, ref_curves = load_tables(clean)
    assert summary.set_index("run_id")["prov_resumed_at_step"].to_dict()[first] == 9
    keep = [c for c in summary.columns if not c.startswith("prov_") and c != "r_wall_time"]
    pd.testing.assert_frame_equal(summary[keep], ref_summary[keep], check_exact=True)
    pd.testing.assert_frame_equal(curves, ref_curves, check_exact=True)


def test_a_campaign_run_keeps_its_checkpoint_until_the_campaign_stored_it(tmp_path):
    """The worker removed the checkpoint when its run ended, before the campaign process
    had the result: a campaign stopped then lost both."""
    from tfm.campaign.runner import execute

    spec = spec_from_dict({"name": "keep", "base": {"spacing": "1/32", "k_th": 0.02, "shape": "paraboloid",
                                                    "max_indent": 0.02, "step": 1e-3}})
    (run,) = spec.runs
    store = CampaignStore.for_spec(spec, tmp_path)
    outcome = execute(run.params, ckpt=(store, 0))        # the work of a campaign worker
    assert outcome.result is not None, outcome.error
    assert tfm.checkpoint.read_meta(store.checkpoint_path(run.run_id))["run_id"] == run.run_id
    store.write_run(run, outcome.result)
    assert store.run_metadata(run.run_id) is not None
    assert not store.checkpoint_path(run.run_id).exists()


def test_a_campaign_says_when_it_sets_a_checkpoint_aside(tmp_path, capsys):
    """A campaign silenced every RunWarning of its runs, and the checkpoint's "starts
    afresh" was one: the user never learnt that saved work was not used."""
    spec = spec_from_dict({"name": "aside", "base": {"spacing": "1/32", "k_th": 0.02, "shape": "paraboloid",
                                                     "max_indent": 0.02, "step": 1e-3}})
    (run,) = spec.runs
    store = CampaignStore.for_spec(spec, tmp_path)
    other = run.params.replace(alpha=0.5)
    with pytest.raises(Stop):              # another run's state at this run's checkpoint
        simulate(other, progress=stop_after(3), checkpoint=store.checkpoint_path(run.run_id),
                 checkpoint_every=0)
    run_campaign(spec, results_dir=tmp_path)
    err = capsys.readouterr().err
    assert f"run 0 {run.run_id}: checkpoint" in err and f"belongs to run '{other.run_id}'" in err
    summary, _ = load_tables(store.root)
    assert "starts afresh" in summary["prov_checkpoint_set_aside"].iloc[0]
    assert summary["prov_resumed_at_step"].iloc[0] == 0


def test_a_campaign_says_when_its_checkpoints_cannot_be_saved(tmp_path, capsys, monkeypatch):
    """A full disk: every checkpoint save of a campaign run failed, and the campaign said
    "1 runs done", exit 0, with nothing in its tables (tfm run warns)."""
    import errno

    def full_disk(fh, **arrays):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(tfm.checkpoint.np, "savez", full_disk)
    spec = spec_from_dict({"name": "full", "base": {"spacing": "1/32", "k_th": 0.02, "shape": "paraboloid",
                                                    "max_indent": 0.02, "step": 1e-3}})
    (run,) = spec.runs
    run_campaign(spec, results_dir=tmp_path, checkpoint_every=0, quiet=True)      # quiet too
    err = capsys.readouterr().err
    assert f"warning: run 0 {run.run_id}: " in err and "checkpoint save(s) failed (cannot save the checkpoint" in err
    assert "No space left on device); the run went on without one" in err
    summary, _ = load_tables(CampaignStore.for_spec(spec, tmp_path).root)
    assert summary["prov_checkpoint_failed_saves"].iloc[0] > 0
    assert summary["prov_checkpoint_save_error"].iloc[0].endswith("No space left on device")


CLI_RUN = ["run", "--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.02",
           "--step", "1e-3", "--no-plot"]


def test_tfm_run_continues_a_killed_run_from_its_checkpoint(reference, tmp_path, capsys):
    """The same `tfm run` command twice: the first is killed after 8 steps (its checkpoint,
    saved after every step, stays beside the table), the second continues at step 7 and
    writes the uninterrupted curve."""
    import pyarrow.parquet as pq

    out = tmp_path / "curve.parquet"
    args = [*CLI_RUN, "-o", str(out), "--checkpoint-every", "0"]
    with crash_after(8), pytest.raises(RuntimeError, match="simulated crash"):
        tfm_main(args)
    saved = tmp_path / "curve.checkpoint.npz"
    assert not out.exists() and tfm.checkpoint.read_meta(saved)["steps"] == 7
    capsys.readouterr()
    assert tfm_main(args) == 0
    assert "continued from the checkpoint" in capsys.readouterr().err and not saved.exists()
    curve = pq.read_table(out).to_pandas()
    pd.testing.assert_frame_equal(curve, reference.curve, check_exact=True)


@pytest.mark.parametrize("extra, expected", [
    (["--checkpoint-every", "-5"], "checkpoint-every: must be >= 0"),
    (["--checkpoint-every", "60", "--snapshots", "5"], "only displacement-controlled runs without field"),
    (["--checkpoint-every", "60", "--no-checkpoints"], "not both"),
])
def test_tfm_run_refuses_a_checkpoint_that_cannot_serve(tmp_path, capsys, extra, expected):
    assert tfm_main([*CLI_RUN, "-o", str(tmp_path / "c.parquet"), *extra]) == 2
    assert expected in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("kw", [dict(), dict(snapshots="events"), dict(control="force", max_indent="auto")])
def test_ctrl_c_without_a_checkpoint_waits_for_the_step_in_progress(tmp_path, capsys, kw):
    """Without a checkpoint (force control, field snapshots, --no-checkpoints), Ctrl-C
    raised KeyboardInterrupt wherever it landed; inside the argument handling of a compiled
    call it came out as a TypeError traceback (1 of 8 timed tries of `tfm run`). Now the
    signal waits for the end of the step in progress there too, then KeyboardInterrupt."""
    p = P.replace(**kw)
    handlers = []

    def progress(rec):
        handlers.append(signal.getsignal(signal.SIGINT))
        if rec.step + 1 == 5:
            os.kill(os.getpid(), signal.SIGINT)

    fields = tmp_path / "run.fields.nc" if p.snapshots != "none" else None
    with pytest.raises(KeyboardInterrupt):
        simulate(p, progress=progress, fields_path=fields)
    assert "SIGINT: stopping after the step in progress (a second signal" in capsys.readouterr().err
    assert len(handlers) == 5                 # it stopped after that step
    assert all(h is not signal.default_int_handler for h in handlers)   # deferred all along
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_while_the_run_is_set_up_stops_it_once_set_up(monkeypatch, capsys):
    """Ctrl-C while the compiled kernels loaded from Numba's cache was swallowed by a ctypes
    callback ("Exception ignored on calling ctypes callback function"), and the run went
    on to write its table. Now the signal waits for the end of the set-up, then stops."""
    sim = sys.modules["tfm.simulate"]             # the module (tfm.simulate is the function)
    built = []

    def build_then_signal(q):
        os.kill(os.getpid(), signal.SIGINT)       # lands while the problem is built
        built.append(sim_build(q))
        return built[-1]

    sim_build = sim.build_problem
    monkeypatch.setattr(sim, "build_problem", build_then_signal)
    steps = []
    with pytest.raises(KeyboardInterrupt):
        simulate(P, progress=steps.append)
    assert built and not steps                    # the set-up finished, no step ran
    assert "SIGINT: stopping once the run is set up" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


class _GoneReader:
    """stderr whose reader is gone (Ctrl-C also ends the `tee` that output goes through)."""

    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        pass

    def fileno(self):
        raise OSError("no file descriptor")


def test_ctrl_c_with_stderr_gone_still_saves_the_step(reference, tmp_path, monkeypatch):
    """`tfm campaign run ... 2>&1 | tee log`, then Ctrl-C: the stop message's print raised
    BrokenPipeError inside the run, which was then recorded as failed, with no checkpoint
    saved. The message is dropped now; the state is saved and KeyboardInterrupt comes."""
    path = tmp_path / "run.npz"
    monkeypatch.setattr(sys, "stderr", _GoneReader())
    with pytest.raises(KeyboardInterrupt):
        simulate(P, progress=signal_after(7), checkpoint=path)
    assert tfm.checkpoint.read_meta(path)["steps"] == 7
    monkeypatch.undo()
    assert_same_run(simulate(P, checkpoint=path), reference)


def test_a_checkpoint_that_cannot_be_written_does_not_cost_the_curve(reference, tmp_path, monkeypatch):
    """A full disk: the first periodic save raised OSError (ENOSPC) and ended the run, and
    so did the save of the finished curve before its table, with the whole curve lost
    although the table (37 KB against a 1.3 MB checkpoint at 1/256) would have fit. Now a
    failed save warns once and the run goes on; the curve is the uninterrupted one."""
    import errno

    def full_disk(fh, **arrays):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(tfm.checkpoint.np, "savez", full_disk)
    path = tmp_path / "run.npz"
    with pytest.warns(CheckpointWarning, match="cannot save the checkpoint .*No space left on device; the run "
                                               "goes on without it and tries again every 0 s") as caught:
        res = simulate(P, checkpoint=path, checkpoint_every=0, keep_checkpoint=True)
    assert len([w for w in caught if issubclass(w.category, CheckpointWarning)]) == 1
    assert not path.exists() and not list(tmp_path.iterdir())     # no temporary file left either
    assert_same_run(res, reference)
