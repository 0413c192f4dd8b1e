"""`tfm run`: flags mirror parameters, fractions work, Parquet carries provenance."""
import pandas as pd

from tfm import Params
from tfm.cli import main
from tfm.results import read_metadata


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


def test_tfm_run_bad_flag_value_exits_2(capsys):
    rc = main(["run", "--spacing", "0", "-q"])
    assert rc == 2
    assert "spacing: must be > 0" in capsys.readouterr().err


def test_tfm_run_flags_a_suspect_run_with_exit_3(tmp_path, capsys):
    rc = main(["run", "--spacing", "1/32", "--f-th", "0", "--shape", "paraboloid", "--max-indent", "0.05",
               "--step", "5e-3", "--extent", "0.15", "-o", str(tmp_path / "c.parquet"), "-q", "--no-plot"])
    assert rc == 3
    assert "grid edge" in capsys.readouterr().err


def test_every_parameter_has_a_flag_with_help():
    from tfm.cli import PARAM_HELP
    assert set(PARAM_HELP) == set(Params.field_names())
