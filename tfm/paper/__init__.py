"""Reproduce every result of the paper: ``tfm paper`` (or ``python -m tfm.paper``).

Hulikal, Bhattacharya & Lapusta, "A threshold-force model for adhesion and mode I
fracture". Three steps, one module each:

- ``run``: run (or resume) the campaigns ``campaigns/paper_*.toml`` through
  ``tfm.campaign`` and load their tables;
- ``claims``: one function per figure, from the tables to the paper's claims beside
  tfm's values, the tables and the numbers the discussion quotes (no files written);
- ``report``: the figures (``tfm.plots``) and ``results/paper/REPORT.md``.

``limit`` goes beyond the paper: the continuum limit of the pull-off coefficient
(``tfm limit``, ``make limit``; campaigns/limit_*.toml).
"""
from __future__ import annotations

# The limit study's campaigns, and where `tfm limit` keeps a point per finished run (the
# runs themselves are too large to keep): here, so that `tfm campaign status` can count
# them without loading the analysis.
LIMIT_CAMPAIGNS = (("paraboloid", "limit_sphere"), ("flat punch", "limit_punch"))
POINTS_FILE = "points.csv"
DEFAULT_OUT = "results/limit"          # tfm limit --out: where the repository keeps its points


def kept_limit_points(campaign: str, out: str = DEFAULT_OUT) -> tuple[str, set[str]]:
    """(the points file, the run ids with a kept point) for a limit campaign's name; an
    empty set for another campaign or without the file."""
    import csv
    from pathlib import Path

    path = Path(out) / POINTS_FILE
    if campaign not in {stem for _, stem in LIMIT_CAMPAIGNS} or not path.is_file():
        return str(path), set()
    with open(path, newline="") as fh:
        return str(path), {row["run_id"] for row in csv.DictReader(fh) if row.get("run_id")}


def __getattr__(name):
    # lazy: `tfm --help` registers `tfm paper` without loading pandas (tests/test_cli.py)
    if name == "CAMPAIGNS":
        from .run import CAMPAIGNS

        return CAMPAIGNS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main(argv=None) -> int:
    from .cli import main as _main

    return _main(argv)


__all__ = ["CAMPAIGNS", "main"]
