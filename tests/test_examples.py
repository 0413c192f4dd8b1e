"""CI runs every script in examples/ as a user would, each within a minute."""
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs_within_a_minute(script, tmp_path):
    pytest.importorskip("duckdb")
    pytest.importorskip("xarray")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=120)
    seconds = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert seconds < 60, f"{script.name} took {seconds:.0f} s"
    if script.name == "fields_xarray.py":
        assert (tmp_path / "fields.png").stat().st_size > 10_000
    if script.name == "campaign_tables.py":
        assert "DuckDB" in proc.stdout and (tmp_path / "example_smoke" / "summary.parquet").exists()
