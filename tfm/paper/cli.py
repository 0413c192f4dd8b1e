"""``tfm paper`` (also ``python -m tfm.paper``) and ``tfm limit``."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

PAPER_HELP = "every result of the paper: campaigns, figures, results/paper/REPORT.md"
LIMIT_HELP = "beyond the paper: the continuum limit of the pull-off coefficient (results/limit/)"


def add_paper_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("-j", "--jobs", type=int, default=1, help="parallel runs per campaign (process pool); default 1")
    ap.add_argument("--quick", action="store_true", help="twice the spacing and step: a pipeline check")
    ap.add_argument("--results-dir", default=None, help="campaign tables (default results, or results/quick)")
    ap.add_argument("--out", default=None, help="figures and REPORT.md (default results/paper, or results/quick/paper)")
    ap.add_argument("-q", "--quiet", action="store_true",
                    help="no progress of the campaigns (the claims table is still printed: it is the result)")


def add_limit_arguments(ap: argparse.ArgumentParser) -> None:
    from ..campaign.cli import checkpoint_flag

    ap.add_argument("-j", "--jobs", type=int, default=1, help="parallel runs (process pool); default 1")
    ap.add_argument("--max-ratio", type=float, default=None, metavar="N",
                    help="run only the points with a_c/Δ <= N, as the campaign files name them (8, 16, 32, ...; "
                         "the point named 16 sits at 16.05); the rest stay pending: rerun without it to finish")
    ap.add_argument("--where", action="append", default=[], metavar="KEY=VALUE",
                    help="run only the points with this parameter value, e.g. self_term=3.8 (repeat to "
                         "combine; with --max-ratio both apply)")
    ap.add_argument("--analyse-only", action="store_true",
                    help="run nothing: fit and report the points stored so far (safe while a campaign runs)")
    checkpoint_flag(ap)
    ap.add_argument("--results-dir", default="results", help="campaign tables (default results)")
    ap.add_argument("--out", default="results/limit",
                    help="figure, REPORT.md and the kept points, points.csv, read from there (or, when it has "
                         "none, from results/limit) and rewritten (default results/limit)")
    ap.add_argument("-q", "--quiet", action="store_true",
                    help="no progress of the campaigns and no table of the fits (they are in REPORT.md)")


def _resumable(command: str, work) -> int:
    """``work()``, and on Ctrl-C or SIGTERM one line and the shell's status (130, 143): a
    campaign's own message said to resume with `tfm campaign run`, which redraws no
    figure and writes no report, above a traceback and exit status 1."""
    import signal

    from ..progress import say

    try:
        return work()
    except KeyboardInterrupt as exc:
        stored = str(exc).split(". To resume", 1)[0]       # CampaignInterrupted: what was kept
        say(f"{command}: {stored}. The same {command} command resumes from them" if stored else
            f"{command}: interrupted. Every finished run is stored: the same {command} command resumes from them")
        return 128 + getattr(exc, "signum", signal.SIGINT)


def cmd_paper(args) -> int:
    return _resumable("tfm paper", lambda: _paper(args))


def _paper(args) -> int:
    from ..params import ParameterError
    from . import claims, report
    from .run import run_all

    if args.jobs < 1:
        raise ParameterError(f"jobs: must be a whole number >= 1, got {args.jobs!r}")
    t0 = time.perf_counter()
    start = report.machine()
    results_dir = Path(args.results_dir or ("results/quick" if args.quick else "results"))
    out_dir = Path(args.out or ("results/quick/paper" if args.quick else "results/paper"))
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:                # a file there, or a place that cannot be made
        raise ParameterError(f"out: cannot make the report's folder {out_dir}: {exc.strerror or exc}") from None
    if args.quick and args.results_dir is None:
        results_dir.mkdir(parents=True, exist_ok=True)
        (results_dir / ".gitignore").write_text("# tfm paper --quick: scratch output\n*\n")
    runs = run_all(args.jobs, args.quick, results_dir, quiet=args.quiet)
    findings = {key: claims.CLAIMS[key](run) for key, run in runs.items()}
    figures = report.draw_figures(findings, out_dir)
    res = report.merge(findings)
    from .limit import summary_line

    wall = time.perf_counter() - t0
    report.write_report(out_dir / "REPORT.md", runs, res, figures, wall, args.jobs, start, args.quick,
                        limit_line=None if args.quick else summary_line(Path("results/limit"), out_dir / "REPORT.md"),
                        results_dir=results_dir)
    import pandas as pd

    print(report.md_table(pd.DataFrame([c.__dict__ for c in res.claims])[["section", "claim", "tfm", "agrees"]]))
    print(f"[tfm.paper] wrote {out_dir / 'REPORT.md'} and {len(figures)} figures in {wall:.0f} s", file=sys.stderr)
    failed = [f"{c.section} ({c.claim})" for c in res.claims if c.agrees == "no"]
    if failed:
        # a reproduction that does not reproduce is not a success; at --quick's doubled
        # spacings some claims are expected to fail, and the pipeline check still passed
        print(f"tfm paper: {len(failed)} of the paper's claims do not hold here: {'; '.join(failed)}"
              + (" (expected at --quick's doubled spacings: these numbers check the pipeline)" if args.quick
                 else ""), file=sys.stderr)
        return 0 if args.quick else 1
    return 0


def cmd_limit(args) -> int:
    from .limit import main_limit

    return _resumable("tfm limit", lambda: main_limit(args))


def register(subparsers) -> None:
    """``tfm paper`` and ``tfm limit``."""
    p = subparsers.add_parser("paper", help=PAPER_HELP, description=PAPER_HELP + " (python -m tfm.paper).")
    add_paper_arguments(p)
    p.set_defaults(func=cmd_paper)
    lim = subparsers.add_parser("limit", help=LIMIT_HELP,
                                description=LIMIT_HELP + ": runs campaigns/limit_sphere.toml and "
                                            "limit_punch.toml, fits F = F_inf + C (a_c/Δ)^-p per self term.")
    add_limit_arguments(lim)
    lim.set_defaults(func=cmd_limit)


def main(argv=None) -> int:
    from ..params import ParameterError

    ap = argparse.ArgumentParser(prog="python -m tfm.paper", description=PAPER_HELP)
    add_paper_arguments(ap)
    args = ap.parse_args(argv)
    try:
        return cmd_paper(args)
    except ParameterError as exc:
        print(f"tfm paper: error: {exc}", file=sys.stderr)
        return 2
