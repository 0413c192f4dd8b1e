"""Field snapshots (tfm.snapshots): what is stored agrees with the curve table, exactly."""
import re

import numpy as np
import pandas as pd
import pytest

import tfm
from tfm.campaign import run_campaign, spec_from_dict
from tfm.snapshots import STATE_CONTACT, Fields

STANDARD = dict(alpha=0.75, k_th=0.02, shape="paraboloid", radius=1.0, max_indent=0.05)


@pytest.fixture(scope="module")
def every10(tmp_path_factory):
    path = tmp_path_factory.mktemp("snap") / "curve.fields.nc"
    res = tfm.simulate(spacing=1 / 64, snapshots=10, fields_path=path, **STANDARD)
    return res, Fields(path)


def test_field_sums_reproduce_the_curve_table_exactly(every10):
    res, fields = every10
    curve = res.curve.set_index("step")
    periodic = [s for s in curve.index if s % 10 == 0]
    assert set(periodic) <= set(fields.steps.tolist())
    for step in fields.steps:
        snap = fields.snapshot(step)
        row = curve.loc[step]
        # the same float64 values summed in the same order as the solver's -F.sum(): bit-equal
        assert -snap["F"].ravel().sum() == row["force"]
        assert int((snap["state"] == STATE_CONTACT).sum()) == row["n_contact"]
        assert snap["d"] == row["d"] and snap["n_contact"] == row["n_contact"]


def test_u_on_the_contact_set_is_d_minus_x0(every10):
    res, fields = every10
    tol = res.params.tol
    x0 = fields.x0
    checked = 0
    for step in fields.steps:
        snap = fields.snapshot(step)
        con = snap["state"] == STATE_CONTACT
        if not con.any():
            continue
        target = snap["d"] - x0[con]
        # CG stops at ||d - x0 - C F||_2 <= tol ||d - x0||_2 on the set, which bounds every
        # component; u = C F is then recomputed on the whole grid (round-off ~1e-15 |u|)
        bound = tol * np.linalg.norm(target) + 1e-12 * np.abs(target).max()
        assert np.abs(snap["u"][con] - target).max() <= bound
        checked += 1
    assert checked > 20


def test_events_are_the_curve_extremes(every10):
    res, fields = every10
    c = res.curve
    unload = c[c["phase"] == "unload"]
    assert fields.event_step("max_load") == int(c.loc[c["force"].idxmax(), "step"])
    assert fields.event_step("pull_off") == int(c.loc[c["force"].idxmin(), "step"])
    assert fields.event_step("first_snap") == int(unload[unload["n_snapped"] > 0]["step"].iloc[0])
    assert fields.event_step("last_contact") == int(c[c["n_contact"] > 0]["step"].iloc[-1])
    # each step is stored once, with all its labels
    assert len(set(fields.steps.tolist())) == len(fields.steps)
    i = fields.position(fields.event_step("pull_off"))
    assert "pull_off" in fields.events[i]


def test_no_pull_off_event_without_tension_and_no_last_contact_while_in_contact(tmp_path):
    """A run with no adhesion had a "pull_off" snapshot (titled "pull-off", at P = 0), and a
    run whose unloading stopped in contact had a "last_contact" one (a user's hunt)."""
    plain = tfm.simulate(spacing=1 / 32, f_th=0.0, shape="paraboloid", max_indent=0.05, step=1e-3,
                         snapshots="events", fields_path=tmp_path / "a.fields.nc")
    fields = Fields(tmp_path / "a.fields.nc")
    assert (plain.curve["force"] >= 0).all()                   # it never pulls
    assert "pull_off_step" not in fields.attrs and "last_contact_step" in fields.attrs
    # with F_th = 0 springs snap while loading too; the event is the summary's first snap,
    # an unloading one (it was the loading step 0, drawn by `tfm show` as "first snap")
    unload = plain.curve[plain.curve["phase"] == "unload"]
    first = unload[unload["n_snapped"] > 0].iloc[0]
    assert fields.event_step("first_snap") == int(first["step"])
    assert first["indent"] == plain.summary["first_snap_indent"]
    with pytest.warns(tfm.RunWarning, match="unloading stopped at max_unload_steps"):
        capped = tfm.simulate(spacing=1 / 32, max_unload_steps=5, snapshots="events",
                              fields_path=tmp_path / "b.fields.nc", **STANDARD, step=1e-3)
    fields = Fields(tmp_path / "b.fields.nc")
    assert capped.curve["n_contact"].iloc[-1] > 0               # unloading stopped in contact
    assert "last_contact_step" not in fields.attrs and "max_load_step" in fields.attrs


def test_xarray_opens_the_file_in_one_line(every10):
    xr = pytest.importorskip("xarray")
    res, fields = every10
    ds = xr.open_dataset(fields.path)
    assert ds["F"].dims == ("step", "x", "y")
    assert ds["F"].attrs["units"] == "F*"
    k = fields.event_step("pull_off")
    # the pull-off force is the tension, sum F (F > 0 tension)
    assert float(ds["F"].sel(step=k).sum()) == pytest.approx(res.summary["pull_off_force"], rel=1e-12)
    ds.close()


def test_xarray_gives_the_springs_of_an_irregular_layout_their_coordinates(tmp_path):
    """On a hexagonal or jittered layout x and y were data variables beside a 'spring' axis
    without coordinates, so a field carried no positions (a user's hunt)."""
    xr = pytest.importorskip("xarray")
    res = tfm.simulate(spacing=1 / 16, step=5e-3, snapshots="events", layout="hexagonal", operator="tree",
                       fields_path=tmp_path / "h.fields.nc", **STANDARD)
    with xr.open_dataset(tmp_path / "h.fields.nc") as ds:
        F = ds["F"].sel(step=ds["step"].values[0])
        assert F.dims == ("spring",) and {"x", "y"} <= set(F.coords)
        fields = Fields(tmp_path / "h.fields.nc")
        np.testing.assert_array_equal(F["x"].values, fields.x)
        np.testing.assert_array_equal(F["y"].values, fields.y)
    assert res.summary["unload_complete"]


def test_write_curve_moves_the_fields_beside_the_table(tmp_path):
    res = tfm.simulate(spacing=1 / 16, step=2e-3, snapshots="events", **STANDARD)
    tmp = res.fields_path
    out = res.write_curve(tmp_path / "run.parquet")
    assert not tmp.exists() and (tmp_path / "run.fields.nc").exists()
    assert tfm.results.read_metadata(out)["fields"] == "run.fields.nc"


def test_a_stopped_run_leaves_no_temporary_snapshot_file(tmp_path, monkeypatch):
    """Without fields_path the snapshots go to a temporary file; a run stopped by Ctrl-C
    (or SIGTERM under a checkpoint) left it behind in the temporary folder, empty. A
    fields_path the user gave is theirs: only the half-written .tmp beside it goes."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    def stop(rec):
        if rec.step == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        tfm.simulate(spacing=1 / 16, step=2e-3, snapshots="events", progress=stop, **STANDARD)
    assert list(tmp_path.iterdir()) == []
    mine = tmp_path / "mine.fields.nc"
    mine.write_bytes(b"kept")
    with pytest.raises(KeyboardInterrupt):
        tfm.simulate(spacing=1 / 16, step=2e-3, snapshots="events", progress=stop, fields_path=mine,
                     **STANDARD)
    assert list(tmp_path.iterdir()) == [mine] and mine.read_bytes() == b"kept"


def test_sigterm_leaves_no_half_written_snapshots(tmp_path):
    """SIGTERM's default ends the process without unwinding: the hidden .tmp that the
    snapshots stream to (20 MB at 1/128) stayed beside the table, and a temporary
    snapshot file in the temporary folder (a user's hunt; Ctrl-C removed them)."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).parents[1]
    code = ("import os, signal, tfm\n"
            "def progress(rec):\n"
            "    if rec.step == 4: os.kill(os.getpid(), signal.SIGTERM)\n"
            "kw = dict(spacing=1/16, step=2e-3, alpha=0.75, k_th=0.02, shape='paraboloid', max_indent=0.05,"
            " snapshots=1, progress=progress)\n"
            f"tfm.simulate(fields_path={str(tmp_path / 'run.fields.nc')!r}, **kw)\n")
    for variant in (code, code.replace(f"fields_path={str(tmp_path / 'run.fields.nc')!r}, ", "")):
        proc = subprocess.run([sys.executable, "-c", variant], cwd=repo, capture_output=True, text=True,
                              timeout=300, env={**os.environ, "PYTHONPATH": str(repo), "TMPDIR": str(tmp_path)})
        assert proc.returncode == -signal.SIGTERM, proc.stderr
        assert "SIGTERM: stopping after the step in progress" in proc.stderr
        assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


def test_unwritten_temporary_snapshots_go_when_the_process_exits(tmp_path):
    """simulate(snapshots=...) without fields_path, its result never written: the file
    stayed in /tmp after a normal exit, until a later run's clean-up an hour on (a user's
    hunt). One that write_curve moved beside a table stays there."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).parents[1]
    code = ("import tfm\n"
            "res = tfm.simulate(spacing=1/16, step=2e-3, alpha=0.75, k_th=0.02, shape='paraboloid', max_indent=0.05,"
            " snapshots='events')\n"
            "print(res.fields_path)\n")
    keep = code + f"res.write_curve({str(tmp_path / 'kept' / 'run.parquet')!r})\n"
    (tmp_path / "kept").mkdir()
    for variant in (code, keep):
        proc = subprocess.run([sys.executable, "-c", variant], cwd=repo, capture_output=True, text=True,
                              timeout=300, env={**os.environ, "PYTHONPATH": str(repo), "TMPDIR": str(tmp_path)})
        assert proc.returncode == 0, proc.stderr
        assert Path(proc.stdout.split()[-1]).parent == tmp_path                # it was a temporary file
        assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"]          # the table's folder only
    assert sorted(p.name for p in (tmp_path / "kept").iterdir()) == ["run.fields.nc", "run.parquet"]


def test_snapshots_stop_before_the_disk_is_full_and_the_run_is_kept(tmp_path, monkeypatch):
    """A disk that fills during a run with snapshots: HDF5 raised thousands of errors in its
    destructors and the process died by segfault, with no table. Now the snapshots stop
    while the file can still be closed, the run goes on and is flagged, and the file holds
    every step before."""
    import shutil

    import tfm.snapshots

    real = shutil.disk_usage
    calls = []

    def filling(path):
        calls.append(path)
        free = tfm.snapshots.DISK_RESERVE + (10**9 if len(calls) <= 6 else 0)
        return real(path)._replace(free=free)

    monkeypatch.setattr(tfm.snapshots.shutil, "disk_usage", filling)
    path = tmp_path / "run.fields.nc"
    with pytest.warns(tfm.RunWarning, match="field snapshots stopped at step 6: 64.0+ MiB free on .* under the "
                                            r"64.\d+ MiB kept for the next snapshot and the table; the file holds "
                                            "the steps before"):
        res = tfm.simulate(spacing=1 / 16, step=2e-3, snapshots=1, fields_path=path, **STANDARD)
    assert not res.ok and len(res.curve) > 20
    f = Fields(path)
    assert list(f.steps) == [0, 1, 2, 3, 4, 5]
    assert f.snapshot(5)["force"] == pytest.approx(res.curve["force"].iloc[5], rel=1e-15)
    # free and needed space read differently (both read 64.6 MiB in a hunt)
    free, need = re.search(r"([\d.]+) MiB free on .* under the ([\d.]+) MiB", res.summary["warnings"]).groups()
    assert free != need
    # the views say why events and unloading frames are missing: show blamed "no adhesion"
    # and animate wrote a GIF of one loading frame
    from tfm.viewcli import ViewError, animate, pick_step
    for event in ("pull_off", "max_load"):
        with pytest.raises(ViewError, match=rf"no {event} snapshot: field snapshots stopped at step 6 \(too little "
                                            r"disk space\)"):
            pick_step(f, event)
    with pytest.raises(ViewError, match="no unloading snapshot to animate: field snapshots stopped at step 6 .*"
                                        "--all-phases animates the loading"):
        animate(f, res.curve, res.params, tmp_path / "a.gif")
    assert not (tmp_path / "a.gif").exists()


def test_events_already_in_the_file_keep_their_names_after_the_snapshots_stop(tmp_path, monkeypatch):
    """Snapshots that stopped after the maximum load: that step was in the file (every
    step was stored) but lost its max_load label, which is settled at the end, so `tfm
    show --step max_load` found none (a user's hunt)."""
    import shutil

    import tfm.snapshots

    real = shutil.disk_usage
    calls = []

    def filling(path):
        calls.append(path)
        return real(path)._replace(free=tfm.snapshots.DISK_RESERVE + (10**9 if len(calls) <= 30 else 0))

    monkeypatch.setattr(tfm.snapshots.shutil, "disk_usage", filling)
    path = tmp_path / "run.fields.nc"
    with pytest.warns(tfm.RunWarning, match="field snapshots stopped at step 30"):
        res = tfm.simulate(spacing=1 / 16, step=2e-3, snapshots=1, fields_path=path, **STANDARD)
    top = int(res.curve["step"].iloc[res.curve["force"].to_numpy().argmax()])
    assert top < 30 and Fields(path).event_step("max_load") == top


def test_no_snapshots_no_file(tmp_path):
    res = tfm.simulate(spacing=1 / 16, step=2e-3, **STANDARD)
    assert res.fields_path is None
    res.write_curve(tmp_path / "run.parquet")
    assert list(tmp_path.iterdir()) == [tmp_path / "run.parquet"]


def test_campaign_stores_one_fields_file_per_run_and_points_to_it(tmp_path):
    spec = spec_from_dict({"name": "snap", "base": {"spacing": "1/16", "k_th": 0.02, "shape": "paraboloid",
                                                      "step": 2e-3, "snapshots": "events"},
                           "sweep": {"alpha": [0.5, 0.75]}})
    root = run_campaign(spec, quiet=True, results_dir=tmp_path)
    summary = pd.read_parquet(root / "summary.parquet")
    assert summary["fields_path"].notna().all()
    for rel, rid in zip(summary["fields_path"], summary["run_id"]):
        assert rel == f"runs/{rid}.fields.nc"
        assert Fields(root / rel).attrs["run_id"] == rid
    assert not list((root / "runs").glob(".*"))      # no temporary files left


@pytest.mark.parametrize("bad, message", [
    ({"snapshots": 0}, "snapshots: must be >= 1"),
    ({"snapshots": "evnts"}, "snapshots: expected 'none', 'events' or a whole number"),
    ({"snapshots": 2.5}, "snapshots: expected an integer"),
])
def test_bad_snapshot_values_fail_early(bad, message):
    with pytest.raises(tfm.params.ParameterError, match=message):
        tfm.Params.from_dict(bad)


def test_an_si_runs_file_holds_its_own_record_in_newtons(tmp_path):
    """The file of an SI run carries that run's record and run id (it held the paper-units
    twin's, so it matched no table and had lost E, nu and gamma) and is in newtons and
    metres like the table: read raw, without tfm's views. Forces are F* times the stored
    force_scale (one multiplication: 1e-12 relative covers the summation order)."""
    import h5py
    import json

    from tfm.units import force_scale, to_paper

    path = tmp_path / "si.fields.nc"
    res = tfm.simulate(units="si", youngs_modulus=1e6, poisson_ratio=0.5, work_of_adhesion=0.05, radius=1e-3,
                       shape="paraboloid", spacing=1e-5, step=5e-7, snapshots="events", fields_path=path)
    p = res.params
    with h5py.File(path, "r") as f:
        attrs = dict(f.attrs)
        assert attrs["run_id"] == p.run_id != to_paper(p).run_id
        assert json.loads(attrs["params"])["youngs_modulus"] == 1e6
        assert (attrs["force_unit"], attrs["length_unit"]) == ("N", "m")
        assert attrs["force_scale"] == force_scale(p) > 1e6
        assert f["F"].attrs["units"] == "N" and f["u"].attrs["units"] == "m"
        assert json.loads(attrs["summary"])["force_unit"] == "N"
        by_step = dict(zip(res.curve["step"], res.curve["force"]))
        for i, k in enumerate(f["step"][...]):
            assert f["force"][i] == pytest.approx(by_step[int(k)], rel=1e-12)
            assert -f["F"][i].sum() == pytest.approx(by_step[int(k)], rel=1e-12)
        assert np.nanmax(f["f_th"][...]) == pytest.approx(p.threshold_force, rel=1e-12)
    # and the views, which scale a file to its table's units, leave it as it is
    fields = Fields(path)
    fields.use_force_scale(force_scale(p))
    k = int(fields.steps[-1])
    assert fields.snapshot(k)["force"] == pytest.approx(by_step[k], rel=1e-12)


def test_writing_a_result_twice_leaves_each_table_its_snapshots(tmp_path):
    """The second write_curve moved the snapshots away from the first table, whose
    metadata then named a missing file ('the run stored no field snapshots')."""
    res = tfm.simulate(spacing=1 / 16, step=2e-3, snapshots="events", **STANDARD)
    a, b = res.write_curve(tmp_path / "a.parquet"), res.write_curve(tmp_path / "b.parquet")
    fa, fb = tmp_path / "a.fields.nc", tmp_path / "b.fields.nc"
    assert fa.read_bytes() == fb.read_bytes()
    from tfm.results import read_metadata
    assert read_metadata(a)["fields"] == fa.name and read_metadata(b)["fields"] == fb.name
    with pytest.raises(ValueError, match="must end with .parquet"):
        res.write_curve(tmp_path / "c.csv")


def test_snapshots_at_a_path_of_the_callers_stay_there(tmp_path):
    """write_curve moved the file given as fields_path beside the table: the caller's
    my_fields.nc was gone. It is copied now; a fields_path that is not .nc is refused."""
    mine = tmp_path / "my_fields.nc"
    res = tfm.simulate(spacing=1 / 16, step=5e-3, snapshots="events", fields_path=mine, **STANDARD)
    res.write_curve(tmp_path / "a.parquet")
    assert mine.exists() and (tmp_path / "a.fields.nc").read_bytes() == mine.read_bytes()
    with pytest.raises(tfm.ParameterError, match="fields_path: .*x.txt must end with .nc"):
        tfm.simulate(spacing=1 / 16, snapshots="events", fields_path=tmp_path / "x.txt", **STANDARD)


def test_snapshot_files_are_sized_before_the_run(tmp_path, capsys):
    """--snapshots 1 at a fine spacing filled the disk with no word before the run (a
    916 MB file at 1/256), and --snapshots 10000 on a 130-step run stored step 0 and the
    events with no word either (users' hunts)."""
    from tfm.cli import main
    from tfm.guards import n_springs
    from tfm.snapshots import BYTES_PER_SPRING_RAW, size_note

    p = tfm.Params.from_dict(dict(STANDARD, spacing="1/32", step=1e-3, snapshots=1))
    assert size_note(p) is None                      # 132 snapshots of 841 springs: no note
    # what the estimate promises holds for a real run: at least its count of snapshots,
    # none larger than F, u and the state uncompressed
    res = tfm.simulate(p, fields_path=tmp_path / "s.fields.nc")
    with Fields(res.fields_path) as f:
        stored = len(f.steps)
    assert stored >= 2 * 50 + 1
    assert (tmp_path / "s.fields.nc").stat().st_size <= stored * n_springs(p) * BYTES_PER_SPRING_RAW
    big = p.replace(spacing=1 / 1024, step=2.5e-4)   # 366,025 springs, 200 loading steps
    assert re.search(r"every step of 366,025 springs: at least 401 snapshots .* 0\.82-2\.3 GiB", size_note(big))
    assert size_note(big.replace(snapshots=10)) is None
    assert re.search(r"^snapshots: every 2nd step of 366,025 springs: at least 201 snapshots",
                     size_note(big.replace(snapshots=2)))
    assert size_note(p, folder=tmp_path) is None
    assert main(["run", "--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.05",
                 "--step", "1e-3", "--snapshots", "10000", "-q", "-o", str(tmp_path / "k.parquet")]) == 0
    assert ("tfm: note: snapshots: every 10000th step, but the loading has 50 steps"
            in capsys.readouterr().err)
