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
