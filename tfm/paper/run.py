"""Run (or resume) the paper's campaigns through ``tfm.campaign`` and load their tables.

``--quick`` runs every campaign at twice the spacing and twice the step into
``results/quick/``: a check of the pipeline, not of the paper.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[2]
CAMPAIGN_DIR = REPO / "campaigns"

# (figure key, campaign file stem), in the order of the report
CAMPAIGNS = (
    ("fig2", "paper_fig2_hertz"),
    ("fig3", "paper_fig3_adhesive"),
    ("fig4", "paper_fig4_alpha0"),
    ("fig5", "paper_fig5_alpha075"),
    ("fig6", "paper_fig6_jkr_scaling"),
    ("kernels", "paper_kernels"),
)
# Longest first, so the short campaigns fill in while nothing else is left.
RUN_ORDER = ("fig6", "fig4", "kernels", "fig5", "fig3", "fig2")


@dataclass
class CampaignRun:
    """A campaign's tables, restricted to the runs of its file, and how it was run."""

    key: str
    name: str
    path: Path
    seconds: float
    n_runs: int
    summary: pd.DataFrame
    curves: pd.DataFrame
    description: str = ""
    computed: int = 0          # runs computed by this invocation (the others were stored)

    def curves_by(self, column: str) -> dict:
        """Each run's curve, keyed by one of its parameters (e.g. ``p_spacing``)."""
        return {row[column]: self.curves[self.curves["run_id"] == row["run_id"]].sort_values("step")
                for _, row in self.summary.iterrows()}


def _load_toml(path: Path) -> dict:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _coarsen(value, factor: float):
    from ..params import parse_number

    x = parse_number(value, "spacing") * factor
    frac = Fraction(x).limit_denominator(4096)
    return f"{frac.numerator}/{frac.denominator}" if abs(float(frac) - x) < 1e-12 else x


def quick_spec(path: Path):
    """The campaign at twice the spacing and twice the step (pipeline check only). Runs
    that the coarse guard would refuse there (Fig. 4's alpha = 0 at 1/32: 1.96 springs
    across a_c) run, flagged: their numbers check the pipeline, not the physics."""
    from ..campaign import spec_from_dict
    from ..params import parse_number

    data = _load_toml(path)
    data["name"] = data["name"] + "_quick"
    base = data.setdefault("base", {})
    base["allow"] = ",".join(sorted(set(filter(None, str(base.get("allow", "")).split(","))) | {"coarse"}))
    tables = [data.get("base", {}), data.get("sweep", {})] + list(data.get("zip", []))
    for table in tables:
        for key in list(table):
            vals = table[key]
            many = isinstance(vals, list)
            vals = vals if many else [vals]
            if key == "spacing":
                vals = [_coarsen(v, 2.0) for v in vals]
            elif key == "step":
                vals = [2.0 * parse_number(v, "step") for v in vals]
            table[key] = vals if many else vals[0]
    return spec_from_dict(data, source=f"{path} (quick)")


def load_spec_for(stem: str, quick: bool = False):
    from ..campaign import load_spec

    path = CAMPAIGN_DIR / f"{stem}.toml"
    return quick_spec(path) if quick else load_spec(path)


def run_specs(specs: dict, jobs: int, results_dir: Path, quiet: bool = False, order=None,
              only: dict | None = None, **campaign_options) -> dict[str, tuple[float, int]]:
    """Run (or resume) each campaign with ``tfm.campaign.run_campaign``, one after the
    other, each over ``jobs`` workers; ``only[key]`` (run ids) limits what is computed
    now; ``campaign_options`` go to run_campaign (checkpoint_every). Returns
    ``{key: (seconds, runs computed now)}``."""
    from ..campaign import CampaignStore, run_campaign

    from . import LIMIT_CAMPAIGNS

    limit_names = {stem for _, stem in LIMIT_CAMPAIGNS}
    out = {}
    for key in order or list(specs):
        spec = specs[key]
        store = CampaignStore.for_spec(spec, results_dir)
        stored = len(store.status(spec).done)
        if not quiet:
            print(f"[{'tfm limit' if spec.name in limit_names else 'tfm paper'}] {spec.name}: {len(spec.runs)} runs, "
                  f"{stored} stored", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        run_campaign(spec, jobs=jobs, quiet=quiet, results_dir=results_dir,
                     only=None if only is None else only.get(key, set()), **campaign_options)
        out[key] = (time.perf_counter() - t0, len(store.status(spec).done) - stored)
    return out


def load_run(key: str, spec, path: Path, results_dir: Path, seconds: float = 0.0, computed: int = 0) -> CampaignRun:
    """The tables of a finished campaign, restricted to the runs its file lists now."""
    from ..campaign import load_tables

    summary, curves = load_tables(spec.name, results_dir=results_dir)
    ids = set(spec.run_ids)
    summary = summary[summary["run_id"].isin(ids)].reset_index(drop=True)
    curves = curves[curves["run_id"].isin(ids)].reset_index(drop=True)
    if len(summary) != len(spec.runs):
        raise RuntimeError(f"{spec.name}: {len(spec.runs) - len(summary)} runs failed; see "
                           f"{Path(results_dir) / spec.name / 'failures.parquet'}")
    return CampaignRun(key, spec.name, path, seconds, len(spec.runs), summary, curves, spec.description, computed)


def run_all(jobs: int, quick: bool, results_dir: Path, quiet: bool = False) -> dict[str, CampaignRun]:
    """Run (or resume) every paper campaign, then load its tables."""
    specs = {key: load_spec_for(stem, quick) for key, stem in CAMPAIGNS}     # validate every file first
    done = run_specs(specs, jobs, results_dir, quiet, order=RUN_ORDER)
    return {key: load_run(key, specs[key], CAMPAIGN_DIR / f"{stem}.toml", results_dir, *done[key])
            for key, stem in CAMPAIGNS}
