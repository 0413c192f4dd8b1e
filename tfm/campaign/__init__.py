"""Campaigns: a TOML file of parameter sweeps -> runs -> Parquet tables.

``spec`` expands and validates the file, ``runner`` runs it (serial, process pool or
Dask), ``store`` keeps the atomic per-run files and assembles the campaign tables.
"""
from __future__ import annotations

from pathlib import Path

from .runner import CampaignInterrupted, run_campaign
from .spec import CampaignError, CampaignSpec, Run, load_spec, select_runs, spec_from_dict
from .store import CampaignStore, Status


def campaign_root(name_or_path, results_dir="results") -> Path:
    """The results folder of a campaign given by name, results folder, or campaign file."""
    if isinstance(name_or_path, CampaignSpec):
        return Path(results_dir) / name_or_path.name
    path = Path(name_or_path)
    if path.suffix == ".toml":
        return Path(results_dir) / load_spec(path).name
    if path.is_dir() and ((path / "summary.parquet").exists() or (path / "runs").is_dir()):
        return path
    return Path(results_dir) / str(name_or_path)


def load_tables(name_or_path, results_dir="results") -> tuple[pd.DataFrame, pd.DataFrame]:
    """``(summary, curves)`` of a finished campaign, e.g. ``load_tables("smoke")``."""
    store = CampaignStore(campaign_root(name_or_path, results_dir))
    return store.load("summary"), store.load("curves")


def load_failures(name_or_path, results_dir="results") -> pd.DataFrame:
    return CampaignStore(campaign_root(name_or_path, results_dir)).load("failures")


__all__ = ["CampaignError", "CampaignInterrupted", "CampaignSpec", "CampaignStore", "Run", "Status",
           "campaign_root", "load_failures", "load_spec", "load_tables", "run_campaign", "select_runs", "spec_from_dict"]
