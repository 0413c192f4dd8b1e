"""Run a small campaign, then analyse its tables with pandas and with DuckDB.

    python examples/campaign_tables.py [OUTPUT_DIR]

The campaign (6 runs at spacing 1/32, a few seconds) sweeps alpha and the radius of a
paraboloid; its tables land in OUTPUT_DIR/example_smoke/ (default: a temporary folder).
Column meanings, units and signs: docs/tables.md.
"""
import sys
import tempfile
from pathlib import Path

import duckdb
import pandas as pd

from tfm.campaign import run_campaign, spec_from_dict

SPEC = {
    "name": "example_smoke",
    "description": "coarse paraboloid pull-off: 2 alphas x 3 radii (max_indent follows radius)",
    "base": {"spacing": "1/32", "shape": "paraboloid", "k_th": 0.02, "step": 2e-3, "snapshots": "events"},
    "sweep": {"alpha": [0.5, 0.75]},
    "zip": [{"radius": [0.5, 1.0, 2.0], "max_indent": [0.025, 0.05, 0.1]}],
}


def main(out: Path) -> None:
    root = run_campaign(spec_from_dict(SPEC), jobs=1, quiet=True, results_dir=out)

    # ---- pandas: one row per run (summary), one row per step (curves)
    summary = pd.read_parquet(root / "summary.parquet")
    curves = pd.read_parquet(root / "curves.parquet")
    table = summary.pivot(index="p_radius", columns="p_alpha", values="r_pull_off_force")
    print("pull-off force F_max by radius (rows) and alpha (columns), pandas:")
    print(table.to_string(float_format="{:.3e}".format))
    # F_max / R: JKR says it is independent of R at fixed toughness
    summary["f_per_r"] = summary["r_pull_off_force"] / summary["p_radius"]
    print("\nF_max / R:")
    print(summary.pivot(index="p_radius", columns="p_alpha", values="f_per_r").to_string(float_format="{:.3e}".format))
    # the most tensile step of each run, from the curves table
    idx = curves.groupby("run_id")["force"].idxmin()
    print("\nsteps of maximum tension (curves table):")
    print(curves.loc[idx, ["run_id", "step", "indent", "force", "contact_radius"]].to_string(index=False))

    # ---- DuckDB: SQL straight on the Parquet files, no loading step
    con = duckdb.connect()
    query = f"""
        SELECT s.p_alpha AS alpha, s.p_radius AS radius, s.r_pull_off_force AS f_max,
               count(*) AS n_steps, max(c.n_snapped) AS most_snaps_in_a_step, s.fields_path
        FROM read_parquet('{root / "summary.parquet"}') AS s
        JOIN read_parquet('{root / "curves.parquet"}') AS c USING (run_id)
        GROUP BY ALL ORDER BY alpha, radius
    """
    print("\nDuckDB, summary joined with curves:")
    print(con.sql(query).df().to_string(index=False))
    # the same F_max from both libraries
    duck = con.sql(f"SELECT run_id, r_pull_off_force FROM read_parquet('{root / 'summary.parquet'}')").df()
    assert (duck.set_index("run_id")["r_pull_off_force"]
            == summary.set_index("run_id")["r_pull_off_force"]).all()
    print(f"\ntables in {root}")


if __name__ == "__main__":          # the campaign pool spawns processes: keep the guard
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="tfm-example-")))
