"""`tfm run`: flags mirror parameters, fractions work, Parquet carries provenance; outputs
are checked before the run; entry points; start-up loads no numerical engine."""
import importlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import tfm.checkpoint
from tfm import Params
from tfm.cli import main
from tfm.results import read_metadata

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def test_tfm_run_writes_curve_plot_and_metadata(tmp_path, capsys):
    out = tmp_path / "curve.parquet"
    rc = main(["run", "--spacing", "1/32", "--alpha", "0.75", "--k-th", "0.02", "--radius", "1",
               "--shape", "paraboloid", "--max-indent", "0.02", "--step", "1e-3", "-o", str(out), "-q"])
    assert rc == 0
    df = pd.read_parquet(out)
    assert list(df.columns[:5]) == ["step", "phase", "d", "indent", "force"]
    assert set(df["phase"]) == {"load", "unload"}
    meta = read_metadata(out)
    p = Params.from_dict(meta["params"])
    assert p.spacing == 1 / 32 and p.k_th == 0.02 and p.run_id == meta["run_id"]
    assert meta["version"] and meta["schema_version"] == 1
    assert meta["summary"]["pull_off_force"] > 0
    assert (tmp_path / "curve.png").stat().st_size > 1000
    # pandas shows the record as DataFrame.attrs and keeps it when the frame is written
    # back (it drops the tfm.* keys: a re-saved table had lost its parameters)
    assert df.attrs["tfm"] == meta
    df.to_parquet(tmp_path / "resaved.parquet")
    assert read_metadata(tmp_path / "resaved.parquet") == meta
    assert main(["plot", str(tmp_path / "resaved.parquet"), "-o", str(tmp_path / "resaved.png")]) == 0


def test_the_printed_summary_is_strict_json(tmp_path, capsys):
    """A run without tension has no pull-off indent (NaN): it was printed as NaN, which
    jq and other strict JSON readers refuse. It is null now."""
    import json

    out = tmp_path / "hertz.parquet"
    assert main(["run", "--spacing", "1/16", "--f-th", "0", "--alpha", "0", "--shape", "paraboloid",
                 "--max-indent", "0.02", "--step", "2e-3", "--no-plot", "-o", str(out)]) == 0

    def refuse(name):
        raise ValueError(f"not JSON: {name}")

    shown = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert shown["pull_off_indent"] is None and shown["pull_off_force"] == 0.0


def test_tfm_run_bad_flag_value_exits_2(capsys):
    rc = main(["run", "--spacing", "0", "-q"])
    assert rc == 2
    assert "spacing: must be > 0" in capsys.readouterr().err


@pytest.mark.parametrize("flag, value, message", [("--spacing", "-1/64", "spacing: must be > 0"),
                                                   ("--step", "-1e-3", "step: must be > 0")])
def test_a_negative_value_gets_its_parameters_message(capsys, flag, value, message):
    """`--spacing -1/64` got argparse's "expected one argument": a word starting with '-'
    is taken for an option unless it looks like a plain negative number."""
    assert main(["run", flag, value, "-q"]) == 2
    assert message in capsys.readouterr().err


def test_tfm_run_flags_a_suspect_run_with_exit_3(tmp_path, capsys):
    rc = main(["run", "--spacing", "1/32", "--f-th", "0", "--shape", "paraboloid", "--max-indent", "0.05",
               "--step", "5e-3", "--extent", "0.15", "-o", str(tmp_path / "c.parquet"), "-q", "--no-plot"])
    assert rc == 3
    assert "grid edge" in capsys.readouterr().err


def test_tfm_run_parses_with_the_run_subcommand_alone(capsys):
    """`tfm run` builds only its own subparser (the others import the campaign code): the
    same usage line on an error, the same help, and the same parsed arguments as the whole
    parser; COMMANDS lists the whole parser's subcommands in order."""
    from tfm.cli import COMMANDS, build_parser

    whole, alone = build_parser(), build_parser("run")
    assert whole.format_usage() == alone.format_usage()
    assert tuple(whole._subparsers._group_actions[0].choices) == COMMANDS
    argv = ["run", "--spacing", "1/64", "--alpha", "0.5", "-q"]
    assert vars(whole.parse_args(argv)) == vars(alone.parse_args(argv))
    texts = []
    for parser in (whole, alone):
        with pytest.raises(SystemExit):
            parser.parse_args(["run", "--help"])
        texts.append(capsys.readouterr().out)
        with pytest.raises(SystemExit):
            parser.parse_args(["run", "--no-such-flag"])
        texts.append(capsys.readouterr().err)
    assert texts[0] == texts[2] and texts[1] == texts[3] and "--no-such-flag" in texts[1]


def test_every_parameter_has_a_flag_with_help():
    from tfm.cli import PARAM_HELP
    assert set(PARAM_HELP) == set(Params.field_names())


def test_the_help_of_a_dimensioned_parameter_gives_its_unit(capsys):
    """--spacing, --f-th, --max-load ... said nothing of L*, F*, metres or newtons."""
    from tfm.units import COLUMN_UNITS

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    text = text[text.index("options:"):]
    dims = COLUMN_UNITS["paper"]["parameters"]
    for name, dim in dims.items():
        flag = "--" + name.replace("_", "-")
        after = text[text.index(flag + " VALUE") + len(flag):]
        after = re.split(r" --[a-z-]+ VALUE", after)[0]          # up to the next flag's help
        want = {"length": "[L*; m with --units si]", "force": "[F*; N with --units si]",
                "k_th": "[F*/L*^(2 alpha)]"}[dim]
        assert want in after, (flag, after)


# ---- outputs are checked before any computation ------------------------------------
SMALL = ["--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.02",
         "--step", "1e-3", "-q"]


@pytest.fixture
def no_compute(monkeypatch):
    """Fail the test if a run starts: the refusals below must come first."""
    monkeypatch.setattr(importlib.import_module("tfm.simulate"), "build_problem",
                        lambda p: pytest.fail("the run started before its outputs were checked"))


@pytest.mark.parametrize("args, message", [
    (["-o", "{tmp}/curve.png"], "output: {tmp}/curve.png must end with .parquet"),
    (["-o", "{tmp}/curve.csv"], "must end with .parquet"),
    (["-o", "{tmp}/.parquet"], "output: {tmp}/.parquet needs a file name before .parquet, e.g. {tmp}/curve.parquet"),
    (["-o", "{tmp}/c.parquet", "--plot", "{tmp}/.PNG"], "plot: {tmp}/.PNG needs a file name"),
    (["-o", "{tmp}/missing/curve.parquet"], "the folder {tmp}/missing does not exist"),
    (["-o", "{tmp}/folder.parquet"], "is a folder"),
    (["-o", "/proc/curve.parquet"], "cannot write in /proc"),
    (["-o", "{tmp}/c.parquet", "--plot", "{tmp}/c.parquet"], "suffix|own path|must end"),
    (["-o", "{tmp}/c.parquet", "--plot", "{tmp}/plot.txt"], "plot: .* must end with .png or .pdf or .svg"),
    (["-o", "{tmp}/exists.parquet"], "exists; pass --overwrite"),
    (["-o", "{tmp}/c.parquet", "--plot", "{tmp}/exists.png"], "plot: .*exists.png exists; pass --overwrite"),
])
def test_bad_outputs_are_refused_before_the_run(tmp_path, capsys, no_compute, args, message):
    (tmp_path / "folder.parquet").mkdir()
    (tmp_path / "exists.parquet").write_bytes(b"data")
    (tmp_path / "exists.png").write_bytes(b"data")
    before = sorted(p.name for p in tmp_path.iterdir())
    args = [a.format(tmp=tmp_path) for a in args]
    assert main(["run", *SMALL, *args]) == 2
    assert re.search(message.format(tmp=tmp_path), capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == before          # nothing written, no .tmp
    assert (tmp_path / "exists.parquet").read_bytes() == b"data"


def test_overwrite_replaces_and_the_plot_gets_its_own_path(tmp_path):
    out = tmp_path / "c.parquet"
    out.write_bytes(b"old")
    assert main(["run", *SMALL, "-o", str(out), "--plot", str(tmp_path / "fig.pdf"), "--overwrite"]) == 0
    assert read_metadata(out)["summary"]["pull_off_force"] > 0
    assert (tmp_path / "fig.pdf").read_bytes()[:4] == b"%PDF"
    assert not list(tmp_path.glob(".*"))


def test_plot_and_no_plot_together_are_refused(tmp_path, capsys):
    """--plot was silently ignored beside --no-plot."""
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "--no-plot", "--plot", str(tmp_path / "c.png")]) == 2
    assert "plot: give --plot FILE or --no-plot, not both" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_overwriting_a_table_removes_its_old_snapshots(tmp_path, capsys):
    """A table replaced by a run without snapshots loses the snapshots it had: they belonged
    to the old run, and tfm show drew them beside the new curve. Without --overwrite, a
    snapshots file at the table's place is refused like the table itself."""
    out = tmp_path / "c.parquet"
    fields = tmp_path / "c.fields.nc"
    assert main(["run", *SMALL, "--snapshots", "events", "-o", str(out), "--no-plot"]) == 0
    assert read_metadata(out)["fields"] == fields.name and fields.exists()
    assert main(["run", *SMALL[:-1], "--alpha", "0.5", "-o", str(out), "--no-plot", "--overwrite"]) == 0
    assert "snapshots of the table being replaced, will be removed" in capsys.readouterr().err
    assert not fields.exists() and "fields" not in read_metadata(out)
    out.unlink()
    fields.write_bytes(b"an orphan")
    assert main(["run", *SMALL, "-o", str(out), "--no-plot"]) == 2
    # a run without snapshots was told the file "exists; pass --overwrite to replace it"
    assert (f"snapshots: {fields} exists, the field snapshots of another run at this path; this run stores none "
            "and would remove them") in capsys.readouterr().err and fields.read_bytes() == b"an orphan"


def test_default_output_is_named_by_run_id_so_runs_do_not_clobber(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", *SMALL, "--no-plot"]) == 0
    assert main(["run", *SMALL[:-1], "--alpha", "0.5", "-q", "--no-plot"]) == 0
    runs = sorted((tmp_path / "results" / "runs").iterdir())
    assert len(runs) == 2
    for folder in runs:
        assert read_metadata(folder / "curve.parquet")["run_id"] == folder.name
    # the same run again is refused, not silently redone over the stored one
    assert main(["run", *SMALL, "--no-plot"]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err


SMALL_SI = ["--units", "si", "--youngs-modulus", "1e6", "--poisson-ratio", "0.5", "--work-of-adhesion", "0.05",
            "--radius", "1e-3", "--shape", "paraboloid", "--spacing", "2.4e-5", "--max-indent", "2e-5",
            "--step", "1e-6", "-q"]


@pytest.mark.parametrize("args", [SMALL, SMALL_SI], ids=["paper units", "SI"])
def test_the_figure_worker_draws_what_tfm_run_would_draw_itself(tmp_path, monkeypatch, args):
    """tfm.plot_worker draws the figure from the written table, in its own process; the
    PNG must be the one tfm run draws from its in-memory curve (byte for byte: same
    Matplotlib, same data, same parameter record), in paper and in SI units."""
    from tfm import plot_worker

    started = []
    real_start = plot_worker.start_worker
    monkeypatch.setattr(plot_worker, "start_worker", lambda p: started.append(real_start(p)) or started[-1])
    assert main(["run", *args, "-o", str(tmp_path / "worker.parquet")]) == 0
    assert started and started[0] is not None and started[0].proc.returncode == 0
    monkeypatch.setattr(plot_worker, "start_worker", lambda p: None)
    assert main(["run", *args, "-o", str(tmp_path / "here.parquet")]) == 0
    drawn = (tmp_path / "worker.png").read_bytes()
    assert drawn[:4] == b"\x89PNG" and drawn == (tmp_path / "here.png").read_bytes()
    assert not list(tmp_path.glob(".*"))


def test_a_failing_figure_worker_leaves_the_figure_to_tfm_run(tmp_path, monkeypatch, capsys):
    from tfm.plot_worker import PlotWorker

    monkeypatch.setattr(PlotWorker, "command",
                        (sys.executable, "-c", "import sys; sys.stdin.readline(); sys.exit('no fonts today')"))
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet")]) == 0
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    assert "figure's worker process failed (no fonts today); drawing the figure here" in capsys.readouterr().err


def test_a_failed_run_ends_the_figure_worker(tmp_path, monkeypatch):
    """A run that raises sends the worker no line and ends it: no figure, no temporary
    file, no process left behind."""
    from tfm import plot_worker

    simulate_module = importlib.import_module("tfm.simulate")

    started = []
    real_start = plot_worker.start_worker
    monkeypatch.setattr(plot_worker, "start_worker", lambda p: started.append(real_start(p)) or started[-1])

    def crash(*args, **kwargs):
        raise RuntimeError("the run broke")

    monkeypatch.setattr(simulate_module, "simulate", crash)
    with pytest.raises(RuntimeError, match="the run broke"):
        main(["run", *SMALL, "-o", str(tmp_path / "c.parquet")])
    assert started[0].proc.returncode is not None          # ended and reaped
    assert list(tmp_path.iterdir()) == []


def test_the_figure_worker_draws_without_pandas():
    """The worker is on `tfm run`'s critical path at 1/128: its warm-up ended after the
    curve, and importing pandas was 0.2 s of it. It draws from the curve's own columns
    (tfm.plots.curve_arrays); the test above checks that the figure is the same."""
    code = ("import json, sys; from tfm import plot_worker as w; w._warm(json.dumps({'spacing': 0.0625})); "
            "print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env=ENV)
    assert out.stdout.strip() == "False"


def test_large_grids_get_no_figure_worker():
    from tfm.guards import n_springs
    from tfm.plot_worker import MAX_SPRINGS, start_worker

    p = Params.from_dict({"spacing": "1/512", "k_th": 0.02, "shape": "paraboloid", "max_indent": 0.05})
    assert n_springs(p) > MAX_SPRINGS and start_worker(p) is None


def test_a_failed_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    def broken(table, where, **kw):
        Path(where).write_bytes(b"PAR1 half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pq, "write_table", broken)
    with pytest.raises(OSError, match="No space"):
        main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "--no-plot"])
    # no half table; the finished run stays in its checkpoint (a stop or a failure while
    # the table was written lost the whole run: simulate had removed it), so the same
    # command writes the table without computing again
    assert [p.name for p in tmp_path.iterdir()] == ["c.checkpoint.npz"]
    assert tfm.checkpoint.read_meta(tmp_path / "c.checkpoint.npz")["phase"] == "done"
    monkeypatch.undo()
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "--no-plot", "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.parquet"]


def test_a_failed_write_leaves_no_figure_of_the_worker(tmp_path, monkeypatch):
    """The figure's worker draws while the table is written (tfm.plot_worker): if the
    write fails, its figure must not be left, under any name, nor its process."""
    import pyarrow.parquet as pq

    from tfm import plot_worker

    started = []
    real_start = plot_worker.start_worker
    monkeypatch.setattr(plot_worker, "start_worker", lambda p: started.append(real_start(p)) or started[-1])
    sent, drawn = [], []
    real_send = plot_worker.PlotWorker.send

    def send_and_wait(self, res, plot):
        real_send(self, res, plot)
        sent.append(self.tmp)
        for _ in range(600):                  # until the worker has drawn its figure
            if self.tmp.exists() and self.tmp.stat().st_size > 0:
                break
            time.sleep(0.05)
        drawn.append(self.tmp.exists())

    monkeypatch.setattr(plot_worker.PlotWorker, "send", send_and_wait)

    def broken(table, where, **kw):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pq, "write_table", broken)
    with pytest.raises(OSError, match="No space"):
        main(["run", *SMALL, "-o", str(tmp_path / "c.parquet")])
    assert sent and drawn == [True] and started[0].proc.returncode is not None
    assert [p.name for p in tmp_path.iterdir()] == ["c.checkpoint.npz"]     # the run, kept


def test_tfm_run_as_its_own_process_writes_the_table_and_the_figure(tmp_path):
    """The process path of `tfm run`: the figure's worker, the collector left off during the
    run and frozen at exit (tfm.cli.main). Same table and same PNG bytes as drawn here from
    that table."""
    from tfm.plots import plot_curve
    from tfm.viewcli import load_run

    out = tmp_path / "c.parquet"
    done = subprocess.run([sys.executable, "-m", "tfm", "run", *SMALL, "-o", str(out)], env=ENV,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "worker" not in done.stderr
    curve, params, _ = load_run(out)
    assert read_metadata(out)["summary"]["n_steps"] == len(curve) > 0
    plot_curve(curve, params, tmp_path / "here.png")
    assert (tmp_path / "c.png").read_bytes() == (tmp_path / "here.png").read_bytes()


LEAN_PROBE = """
import sys
import tfm.cli as cli
exit_now = cli.exit_now


def probe(code):                 # the process's last act before os._exit
    print("SCIPY", *[m for m in ("scipy.fft", "scipy.linalg") if m in sys.modules], flush=True)
    exit_now(code)


cli.exit_now = probe
sys.argv[0] = "tfm"
cli.main()
"""


def test_tfm_run_as_its_own_process_starts_lean_and_computes_the_same_curve(tmp_path):
    """`tfm run`'s own process starts rocket-fft and Numba without the SciPy modules they
    import for features the kernels do not use (tfm.kernels.lean_start; 0.1-0.2 s of a 1.2 s
    run at 1/128). Its curve is the in-process one, bit for bit."""
    from tfm import simulate
    from tfm.viewcli import load_run

    out = tmp_path / "c.parquet"
    done = subprocess.run([sys.executable, "-c", LEAN_PROBE, "run", *SMALL, "--no-plot", "-q", "-o", str(out)],
                          env=ENV, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "SCIPY", done.stdout[-300:]
    curve, params, _ = load_run(out)
    pd.testing.assert_frame_equal(curve, simulate(params).curve, check_exact=True)


LEAN_AFTER = """
import sys
import numpy as np
from numba import njit
from tfm.kernels import lean_start

lean_start()
print("IMPORTED", *[m for m in ("scipy.fft", "scipy.linalg") if m in sys.modules])
import scipy.fft, scipy.linalg
a = np.arange(6.0).reshape(2, 3)
print("DOT", njit(lambda x, y: np.dot(x, y))(a, a.T).tolist() == (a @ a.T).tolist(),
      np.allclose(scipy.fft.irfft(scipy.fft.rfft(a[0]), 3), a[0]))
"""


def test_lean_start_leaves_scipy_importable_and_dot_compilable():
    """What lean_start keeps out is only deferred: both modules import afterwards, and a
    compiled np.dot (BLAS through scipy.linalg) still works in that process."""
    done = subprocess.run([sys.executable, "-c", LEAN_AFTER], env=ENV, cwd=REPO, capture_output=True,
                          text=True, timeout=600)
    assert done.stdout.splitlines()[-2:] == ["IMPORTED", "DOT True True"], done.stdout[-300:] + done.stderr


NO_PANDAS_PROBE = """
import sys
from tfm.cli import main
code = main(sys.argv[1:])
print("EXIT", code, "pandas" in sys.modules)
"""


def test_tfm_run_writes_its_table_without_pandas_and_the_table_reads_as_before(tmp_path):
    """Importing pandas took 0.1 s of a 1.4 s `tfm run` (tfm.results.RunResult): the table
    is written from NumPy columns. It must read back as the DataFrame of the run, with
    the column types that pandas itself writes."""
    import pyarrow.parquet as pq

    from tfm import simulate
    from tfm.results import write_table
    from tfm.viewcli import load_run

    out = tmp_path / "c.parquet"
    done = subprocess.run([sys.executable, "-c", NO_PANDAS_PROBE, "run", *SMALL, "--no-plot", "-q", "-o",
                           str(out)], env=ENV, capture_output=True, text=True, timeout=600)
    assert done.stdout.splitlines()[-1] == "EXIT 0 False", done.stdout[-300:] + done.stderr
    _, params, _ = load_run(out)
    frame = simulate(params).curve            # built from the columns when first read
    assert frame["phase"].tolist()[0] == "load" and frame["step"].dtype == "int64"
    via_pandas = write_table(frame, tmp_path / "p.parquet")
    assert pq.read_schema(out).types == pq.read_schema(via_pandas).types
    written = pd.read_parquet(out)
    pd.testing.assert_frame_equal(written, pd.read_parquet(via_pandas))
    pd.testing.assert_frame_equal(written, frame)


# ---- parameters and guards on the command line --------------------------------------
def test_a_parameter_that_does_not_apply_exits_2_or_warns(tmp_path, capsys):
    assert main(["run", *SMALL, "--alpha", "0.5", "--k-th", "none", "--f-th", "1e-5"]) == 2
    assert "alpha: 0.5 has no effect here" in capsys.readouterr().err
    assert main(["run", *SMALL, "--theta", "0.5", "--no-plot", "-o", str(tmp_path / "c.parquet")]) == 0
    assert "tfm: warning: theta: given but has no effect; it applies only when operator='tree'" \
        in capsys.readouterr().err


def test_an_indefinite_kernel_is_refused_before_the_run_is_announced(tmp_path, capsys):
    """The refusal came after the `tfm run <id>: ...` header, as if the run had started."""
    loud = [a for a in SMALL if a != "-q"]
    assert main(["run", *loud, "--kernel", "neighbors", "-o", str(tmp_path / "c.parquet")]) == 2
    err = capsys.readouterr().err
    assert "is not positive definite" in err and "tfm run " not in err and not list(tmp_path.iterdir())


def test_guards_refuse_on_the_command_line_and_allow_overrides(tmp_path, capsys, monkeypatch):
    coarse = ["--spacing", "1/4", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.01",
              "--step", "1e-3", "-q", "--no-plot"]
    with monkeypatch.context() as m:
        m.setattr(importlib.import_module("tfm.simulate"), "build_problem", lambda p: pytest.fail("ran"))
        assert main(["run", *coarse, "-o", str(tmp_path / "a.parquet")]) == 2
    assert "--allow coarse" in capsys.readouterr().err
    assert main(["run", *coarse, "--allow", "coarse", "-o", str(tmp_path / "a.parquet")]) in (0, 3)
    assert (tmp_path / "a.parquet").exists()


def test_a_capped_auto_preload_is_stated_before_the_run_and_flags_it(tmp_path, capsys):
    out = tmp_path / "c.parquet"
    rc = main(["run", "--spacing", "1/64", "--radius", "0.05", "--k-th", "0.05", "--shape", "paraboloid",
               "--step", "1e-3", "--no-plot", "-o", str(out)])
    err = capsys.readouterr().err
    header, note = err.index("tfm run "), err.index("auto preload capped at 0.5 R = 0.025")
    assert header < note < err.index("wrote")                          # said before the run
    assert rc == 3 and "capped" in read_metadata(out)["summary"]["warnings"]


# ---- entry points and start-up time ---------------------------------------------------
def test_version_and_python_m_tfm():
    from tfm import __version__

    for cmd in ([sys.executable, "-m", "tfm", "--version"], [sys.executable, "-m", "tfm.cli", "--version"]):
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=ENV, timeout=60)
        assert out.returncode == 0 and out.stdout.strip() == f"tfm {__version__}", out
    out = subprocess.run([sys.executable, "-m", "tfm", "run", "--help"], capture_output=True, text=True,
                         cwd=REPO, env=ENV, timeout=60)
    assert out.returncode == 0 and "--overwrite" in out.stdout and "--allow" in out.stdout


HEAVY = ("numba", "scipy", "pandas", "matplotlib")
PROBE = """
import sys
from tfm.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print("HEAVY", *[m for m in {heavy!r} if m in sys.modules])
"""


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["campaign", "status", "campaigns/smoke.toml"]])
def test_help_and_status_load_no_numerical_engine(argv, tmp_path):
    argv = argv + (["--results-dir", str(tmp_path)] if "status" in argv else [])
    out = subprocess.run([sys.executable, "-c", PROBE.format(heavy=HEAVY), *argv], capture_output=True,
                         text=True, cwd=REPO, env=ENV, timeout=60)
    assert out.stdout.splitlines()[-1] == "HEAVY", out.stdout[-300:] + out.stderr


BLAS_PROBE = """
import os, sys
from tfm.cli import main
sys.argv = ["tfm", "--version"]
try:
    main()
except SystemExit:
    pass
print("BLAS", os.environ.get("OPENBLAS_NUM_THREADS"))
"""


@pytest.mark.parametrize("given, expected", [(None, "1"), ("3", "3")])
def test_the_tfm_process_keeps_openblas_to_one_thread_unless_told(given, expected):
    """OpenBLAS's idle threads spun 0.3 s of CPU in a 1.5 s `tfm run` (tfm.cli.main): the
    command sets one thread before NumPy loads, and a user's own setting stands."""
    env = {k: v for k, v in ENV.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    out = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True, cwd=REPO,
                         env=env, timeout=60)
    assert out.stdout.splitlines()[-1] == f"BLAS {expected}", out.stdout[-300:] + out.stderr


def _killed_run_checkpoint(ckpt):
    """The saved state of a run killed at its 15th step (k_th 0.02 at 1/32), as bytes."""
    import tfm

    seen = []

    def stop(rec):
        seen.append(rec)
        if len(seen) == 15:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        tfm.simulate(spacing=1 / 32, k_th=0.02, shape="paraboloid", max_indent=0.05, step=2.5e-3,
                     checkpoint=ckpt, checkpoint_every=0, progress=stop)
    return ckpt.read_bytes()


def test_another_runs_checkpoint_is_not_discarded_without_overwrite(tmp_path, capsys):
    """A killed run left its state beside the table; a run with other parameters and the
    same -o set that state aside and removed it without a word (hours of work, for a long
    run). Now it is refused; with --overwrite it is discarded, saying so."""
    out, ckpt = tmp_path / "kk.parquet", tmp_path / "kk.checkpoint.npz"
    saved = _killed_run_checkpoint(ckpt)
    other = ["run", "--spacing", "1/32", "--k-th", "0.03", "--shape", "paraboloid", "--max-indent", "0.05",
             "--step", "2.5e-3", "--no-plot", "-o", str(out)]
    capsys.readouterr()
    assert main(other) == 2
    assert "holds the saved state of another run" in capsys.readouterr().err
    assert ckpt.read_bytes() == saved and not out.exists()
    # a damaged checkpoint, even of this very run: "rerun that run's command to continue
    # it" told the user to do what they had just done
    ckpt.write_bytes(saved[:100])
    assert main(other) == 2
    assert "no run can continue from it (damaged, or not a checkpoint): pass --overwrite to discard it" \
        in capsys.readouterr().err
    ckpt.write_bytes(saved)
    assert main([*other, "--overwrite"]) == 0
    assert "the run starts afresh" in capsys.readouterr().err
    assert not ckpt.exists() and out.exists()


def test_a_table_written_by_another_run_meanwhile_is_not_replaced(tmp_path, monkeypatch, capsys):
    """Two tfm run into one -o: the second to finish replaced the first's table though
    neither had --overwrite. Now its table goes beside, named by its run id."""
    import tfm.simulate  # noqa: F401  (the package attribute is the function)
    sim_module = sys.modules["tfm.simulate"]

    out = tmp_path / "same.parquet"
    real = sim_module.simulate

    def other_run_finishes_first(*a, **k):
        res = real(*a, **k)
        out.write_bytes(b"the other run's table")
        return res

    monkeypatch.setattr(sim_module, "simulate", other_run_finishes_first)
    assert main(["run", *SMALL[:-1], "-o", str(out)]) == 0
    assert "appeared while this run computed" in capsys.readouterr().err
    assert out.read_bytes() == b"the other run's table"
    p = Params.from_dict(read_metadata(next(tmp_path.glob("same.*.parquet")))["params"])
    assert (tmp_path / f"same.{p.run_id}.parquet").exists() and (tmp_path / f"same.{p.run_id}.png").exists()


def test_an_interrupted_run_says_what_survives_without_a_traceback(tmp_path, monkeypatch, capsys):
    import tfm.simulate  # noqa: F401  (the package attribute is the function)
    sim_module = sys.modules["tfm.simulate"]

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(sim_module, "simulate", interrupted)
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "--no-plot"]) == 130
    assert "interrupted: no table written; it was stopped before its first step was saved" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
    # a run that keeps no checkpoint was told "--checkpoint-every SECONDS saves more often"
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "--no-plot", "--no-checkpoints"]) == 130
    assert "this run keeps no checkpoint" in capsys.readouterr().err


def test_help_names_every_shape_and_make_help_lists_the_targets():
    from tfm.cli import PARAM_HELP
    from tfm.params import SHAPES

    assert all(s in PARAM_HELP["shape"] for s in SHAPES)
    out = subprocess.run(["make", "-s", "help"], cwd=REPO, capture_output=True, text=True)
    assert out.returncode == 0 and "install" in out.stdout and "bench" in out.stdout


def test_a_default_figure_written_by_another_run_meanwhile_is_not_replaced(tmp_path, monkeypatch, capsys):
    """The table was diverted when another run wrote it meanwhile, but the default figure
    beside it (not given by --plot) was replaced without a word."""
    import tfm.simulate  # noqa: F401  (the package attribute is the function)
    sim_module = sys.modules["tfm.simulate"]

    out = tmp_path / "same.parquet"
    real = sim_module.simulate

    def other_figure_appears(*a, **k):
        res = real(*a, **k)
        out.with_suffix(".png").write_bytes(b"the other run's figure")
        return res

    monkeypatch.setattr(sim_module, "simulate", other_figure_appears)
    assert main(["run", *SMALL[:-1], "-o", str(out)]) == 0
    assert "appeared while this run computed" in capsys.readouterr().err
    assert out.with_suffix(".png").read_bytes() == b"the other run's figure" and out.exists()
    p = Params.from_dict(read_metadata(out)["params"])
    assert (tmp_path / f"same.{p.run_id}.png").read_bytes()[:4] == b"\x89PNG"


def _watch_worker(monkeypatch):
    from tfm import plot_worker

    started = []
    real_start = plot_worker.start_worker
    monkeypatch.setattr(plot_worker, "start_worker", lambda p: started.append(real_start(p)) or started[-1])
    return started


def test_a_worker_that_does_not_read_holds_up_neither_table_nor_figure(tmp_path, monkeypatch, capsys):
    """The curve goes to the figure's worker before the table is written; a curve of 500
    steps and more is longer than a pipe's buffer, and a worker that does not read (here:
    never) held `tfm run` before its table, for as long as it did not read. Now the table is
    written, and after WAIT seconds tfm run draws the figure itself."""
    from tfm import plot_worker

    monkeypatch.setattr(plot_worker, "WAIT", 3.0)
    monkeypatch.setattr(plot_worker.PlotWorker, "command", (sys.executable, "-c", "import time; time.sleep(300)"))
    started = _watch_worker(monkeypatch)
    out = tmp_path / "c.parquet"
    args = ["run", *SMALL[:-3], "--step", "2e-5", "-q", "-o", str(out)]     # 2000 steps, a 200 kB line
    assert main(args) == 0
    assert "worker process failed (no answer after 3 s); drawing the figure here" in capsys.readouterr().err
    assert read_metadata(out)["summary"]["n_steps"] > 1000
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    assert started[0].proc.returncode is not None and not list(tmp_path.glob(".*"))


def test_an_interruption_after_the_table_says_so_and_leaves_no_figure_behind(tmp_path, monkeypatch, capsys):
    """Ctrl-C while tfm run waits for its figure: the worker's file was left under a hidden
    temporary name, and the message said that no table was written."""
    from tfm import plot_worker

    def interrupted(self):
        for _ in range(600):                       # until the worker has drawn its figure
            if self.tmp.exists() and self.tmp.stat().st_size > 0:
                break
            time.sleep(0.05)
        raise KeyboardInterrupt

    monkeypatch.setattr(plot_worker.PlotWorker, "finish", interrupted)
    started = _watch_worker(monkeypatch)
    out = tmp_path / "c.parquet"
    assert main(["run", *SMALL, "-o", str(out)]) == 130
    assert f"the table {out} was written, the figure was not" in capsys.readouterr().err
    assert out.exists() and started[0].proc.returncode is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.parquet"]


def test_an_interruption_before_the_table_leaves_no_snapshots_that_block_the_rerun(tmp_path, monkeypatch,
                                                                                   capsys):
    """Ctrl-C after the run, before its table: the snapshots were in place with no table,
    and the command the message gave was refused ("a.fields.nc exists")."""
    from tfm.results import RunResult

    real = RunResult.write_curve

    def interrupted(self, path):
        raise KeyboardInterrupt

    monkeypatch.setattr(RunResult, "write_curve", interrupted)
    out = tmp_path / "a.parquet"
    cmd = ["run", *SMALL, "--snapshots", "5", "--no-plot", "-o", str(out)]
    assert main(cmd) == 130
    assert "no table written" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(RunResult, "write_curve", real)
    assert main(cmd) == 0                                    # the same command, as the message says
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.fields.nc", "a.parquet"]


def test_write_table_keeps_every_numpy_column_type():
    """Columns are written from their buffers without pandas (tfm.results.arrow_column);
    booleans (bits in Arrow), big-endian numbers and NumPy strings must survive too."""
    import numpy as np

    from tfm.results import write_table

    n = 9
    cols = {"b": np.array([True, False, True, False, False, True, True, True, False]),
            "big": np.arange(n, dtype=">f8") + 0.5, "i32": np.arange(n, dtype=np.int32),
            "u": np.array(["load"] * 4 + ["unload"] * 5), "o": np.array(["x"] * n, dtype=object),
            "f": np.linspace(0.0, 1.0, n)}
    with __import__("tempfile").TemporaryDirectory() as tmp:
        df = pd.read_parquet(write_table(cols, Path(tmp) / "t.parquet"))
    for name, values in cols.items():
        assert df[name].tolist() == values.tolist(), name


def test_a_run_result_pickled_by_the_dataclass_version_still_loads(tmp_path):
    """RunResult was a dataclass with a ``curve`` field until its curve became NumPy
    columns made into a DataFrame on demand: its pickles (a campaign's results in flight)
    must still give the curve and write their table."""
    import pickle

    from tfm import simulate
    from tfm.results import RunResult

    res = simulate(_params_from(SMALL))
    old = RunResult.__new__(RunResult)
    old.__dict__.update(params=res.params, curve=res.curve, summary=res.summary, provenance=res.provenance,
                        fields_path=None)            # the dataclass's fields, as its pickle held them
    loaded = pickle.loads(pickle.dumps(old))
    pd.testing.assert_frame_equal(loaded.curve, res.curve)
    loaded.write_curve(tmp_path / "old.parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "old.parquet"), res.curve)


def _params_from(argv):
    from tfm.cli import _params_from_args, build_parser

    return _params_from_args(build_parser().parse_args(["run", *argv]))


def test_provenance_leaves_the_users_git_index_alone(tmp_path):
    """A run's provenance asks git whether the checkout is dirty. Plain `git status`
    rewrites a stale index under .git/index.lock; a run killed meanwhile left the lock,
    and every git command in the user's checkout failed after (found after a test run)."""
    from tfm.results import git_commit

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=tmp_path, check=True,
                       capture_output=True)

    git("init", "-q")
    (tmp_path / "a.txt").write_text("a")
    git("add", "a.txt")
    git("commit", "-qm", "a")
    index = tmp_path / ".git" / "index"
    before = index.read_bytes()
    os.utime(tmp_path / "a.txt", (1e9, 1e9))          # same content, other stat: the index is stale
    assert git_commit(tmp_path).endswith("-dirty") is False
    assert index.read_bytes() == before


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_run_removes_what_a_killed_run_of_the_same_outputs_left(tmp_path):
    """kill -9 during a write left the temporary files of the table, the checkpoint and the
    figure beside the outputs for good; the next run of those outputs removes the files of
    pids that no longer run, and nothing else."""
    dead, alive = _dead_pid(), os.getppid()      # not ours: this process writes through its own
    left = [f".c.parquet.{dead}.tmp", f".c.checkpoint.npz.{dead}.tmp", f".c.{dead}.tmp.png",
            f".c.{dead}.worker.png", f".c.fields.nc.{dead}.tmp"]
    kept = [f".c.parquet.{alive}.tmp", ".c.parquet.backup", f".d.parquet.{dead}.tmp", f".c.parquet.{dead}.tmp.x"]
    for name in left + kept:
        (tmp_path / name).write_text("x")
    assert main(["run", *SMALL, "-o", str(tmp_path / "c.parquet"), "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept + ["c.parquet", "c.png"])


def test_temporary_snapshot_files_of_dead_processes_are_removed(tmp_path):
    from tfm.snapshots import remove_dead_temporary_fields

    dead, alive = _dead_pid(), os.getpid()
    left = [f"tfm-{dead}-abc.fields.nc", f".tfm-{dead}-abc.fields.nc.{dead}.tmp"]
    kept = [f"tfm-{alive}-abc.fields.nc", "tfm-abc.fields.nc", f"tfm-{dead}-abc.fields.nc.bak"]
    for name in left + kept:
        (tmp_path / name).write_text("x")
    assert remove_dead_temporary_fields(tmp_path) == []          # younger than an hour: kept
    assert sorted(p.name for p in remove_dead_temporary_fields(tmp_path, min_age=0)) == sorted(left)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept)


@pytest.mark.parametrize("name, value", [("NUMBA_NUM_THREADS", "0"), ("NUMBA_NUM_THREADS", "-1"),
                                         ("OMP_NUM_THREADS", "abc")])
def test_a_bad_thread_count_in_the_environment_is_refused_by_name(monkeypatch, capsys, name, value):
    """NUMBA_NUM_THREADS=0 gave a traceback from Numba's import, OMP_NUM_THREADS=abc
    "internal error in the DUCC0 backend" from the first FFT."""
    from tfm.cli import main

    monkeypatch.setenv(name, value)
    assert main(["campaign", "list"]) == 2
    assert f"tfm: error: {name}: the environment variable must be a whole number >= 1 (threads), got {value!r}" \
        in capsys.readouterr().err


def test_a_figure_that_cannot_be_written_keeps_the_table_and_the_summary(tmp_path, monkeypatch, capsys):
    """A disk that filled before the figure: the table was written, then the figure's
    OSError ended `tfm run` with a traceback, and the summary and flags were never printed."""
    import errno

    import tfm.plot_worker
    import tfm.plots
    from tfm.cli import main

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(tfm.plot_worker, "start_worker", lambda p: None)     # draw in this process
    monkeypatch.setattr(tfm.plots, "write_curve_figure", full)
    out = tmp_path / "r.parquet"
    assert main(["run", "--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.02",
                 "--step", "1e-3", "-o", str(out)]) == 1
    captured = capsys.readouterr()
    assert f"tfm: error: the figure {tmp_path / 'r.png'} could not be written (No space left on device); the " \
           f"table {out} is" in captured.err
    assert out.exists() and not (tmp_path / "r.png").exists() and '"pull_off_force"' in captured.out


def test_a_note_stated_before_the_run_is_not_repeated_after_it(tmp_path, capsys):
    """An allowed guard or a capped preload was printed before the run and again, in the
    summary's warnings, after it. Still exit 3, the reason said once."""
    from tfm.cli import main

    assert main(["run", "--spacing", "1/16", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.01",
                 "--step", "1e-3", "--allow", "coarse", "--no-plot", "-o", str(tmp_path / "r.parquet")]) == 3
    err = capsys.readouterr().err
    assert err.count("allowed past the 'coarse' guard") == 1


def test_a_run_without_checkpoints_does_not_bury_another_runs_saved_state(tmp_path, capsys):
    """A run that keeps no checkpoint (snapshots, force control, --no-checkpoints) wrote
    its table beside another killed run's saved state without a word, and that state was
    later continued over the new table (a user's hunt). Now it is refused as for a
    checkpointed run; with --overwrite the state is discarded once the table is written."""
    out, ckpt = tmp_path / "kk.parquet", tmp_path / "kk.checkpoint.npz"
    saved = _killed_run_checkpoint(ckpt)
    base = ["run", "--spacing", "1/32", "--k-th", "0.03", "--shape", "paraboloid", "--max-indent", "0.05",
            "--step", "2.5e-3", "--no-plot", "-o", str(out)]
    for extra in (["--snapshots", "events"], ["--no-checkpoints"], ["--control", "force"]):
        capsys.readouterr()
        assert main([*base, *extra]) == 2, extra
        assert "holds the saved state of another run" in capsys.readouterr().err
        assert ckpt.read_bytes() == saved and not out.exists()
    assert main([*base, "--no-checkpoints", "--overwrite"]) == 0
    assert not ckpt.exists() and out.exists()


def test_the_header_gives_the_units_of_an_si_run_and_the_trees_angle(tmp_path, capsys, monkeypatch):
    """An SI run's header printed spacing=1e-05 F_th=1.14e-05 R=0.001 without m or N, and a
    tree run's header no theta (the summary carries neither)."""
    from tfm.plots import spacing_text

    class Announced(BaseException):
        pass

    def stop(p):
        raise Announced
    monkeypatch.setattr(importlib.import_module("tfm.simulate"), "build_problem", stop)
    for args in ([a for a in SMALL_SI if a != "-q"], [*SMALL[:-1], "--operator", "tree", "--theta", "0.6"]):
        with pytest.raises(Announced):
            main(["run", *args, "--no-plot", "-o", str(tmp_path / "c.parquet")])
    si, tree = [line for line in capsys.readouterr().err.splitlines() if line.startswith("tfm run ")]
    assert re.search(r"spacing=\S+ m F_th=\S+ N R=0.001 m .* max_indent=\S+ m \(", si), si
    assert "operator=tree theta=0.6 " in tree and "layout=" not in tree
    # a jittered run's header names its layout (it read like a square grid's)
    with pytest.raises(Announced):
        main(["run", *SMALL[:-1], "--operator", "tree", "--layout", "jittered", "--jitter", "0.2", "--seed", "3",
              "--no-plot", "-o", str(tmp_path / "j.parquet")])
    jittered = [line for line in capsys.readouterr().err.splitlines() if line.startswith("tfm run ")][0]
    assert " shape=paraboloid layout=jittered jitter=0.2 seed=3 kernel=" in jittered, jittered
    # and an SI spacing is no fraction in a caption: 1e-5 m was "1/100000 m"
    assert spacing_text(1e-5) == "$10^{-5}$" and spacing_text(1 / 128) == "1/128"
