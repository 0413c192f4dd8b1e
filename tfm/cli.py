"""Command line: `tfm run` (one curve), `tfm campaign ...` (grids of runs)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from .params import ParameterError, Params
from .viewcli import register as register_views


PARAM_HELP = {
    "spacing": "spring spacing Delta, e.g. 1/128",
    "alpha": "threshold exponent: F_th = k_th * A^alpha",
    "k_th": "threshold parameter K_th (sets f_th to none)",
    "f_th": "explicit threshold force F_th",
    "radius": "radius R of the body",
    "shape": "sphere | paraboloid | flat_punch",
    "kernel": "boussinesq | local | neighbors",
    "self_term": "C_ii = self_term / sqrt(A) (the paper's 3.8)",
    "neighbor_rings": "kernel=neighbors: keep 1/r for r <= m * spacing",
    "c_w": "kernel=local: Winkler compliance, C_ii = c_w / A",
    "operator": "fft | direct | tree",
    "theta": "operator=tree: opening angle (0, 1]",
    "layout": "square | hexagonal | jittered",
    "jitter": "layout=jittered: offsets in spacings, [0, 0.5)",
    "seed": "layout=jittered: random seed",
    "max_indent": "preload delta_max, or auto (deep enough for the JKR pull-off)",
    "step": "dilatation step",
    "snap_rule": "batch (the paper) | single",
    "tol": "relative residual of the contact solve",
    "max_iter": "CG iterations per solve (hitting it is flagged)",
    "max_rounds": "snap/enter rounds per step (hitting it is flagged)",
    "max_unload_steps": "cap on unloading steps (default 20 x loading steps + 1000)",
    "preconditioner": "auto | fft | stencil | diagonal | none",
    "extent": "grid half-width (default: from the Hertz radius at max_indent)",
    "extent_margin": "auto extent = margin * contact radius + 4 spacings",
}


def _add_param_flags(parser: argparse.ArgumentParser) -> None:
    """One flag per parameter, named like the field with dashes (--k-th, --max-indent)."""
    defaults = Params()
    for f in dataclasses.fields(Params):
        flag = "--" + f.name.replace("_", "-")
        default = getattr(defaults, f.name)
        parser.add_argument(flag, dest=f.name, default=None, metavar="VALUE",
                            help=f"{PARAM_HELP.get(f.name, '')} (default: {default!r})")


def _params_from_args(args) -> Params:
    values = {}
    for name in Params.field_names():
        raw = getattr(args, name)
        if raw is None:
            continue
        values[name] = None if raw.lower() in ("none", "null") else raw
    return Params.from_dict(values)


def cmd_run(args) -> int:
    import warnings

    from .plots import plot_curve
    from .simulate import RunWarning, simulate

    p = _params_from_args(args)
    out = Path(args.output)
    if not args.quiet:
        print(f"tfm run {p.run_id}: spacing={p.spacing:.6g} F_th={p.threshold_force:.4g} "
              f"R={p.radius:g} shape={p.shape} kernel={p.kernel} operator={p.operator} "
              f"max_indent={p.delta_max:.4g}", file=sys.stderr)
    from .progress import run_progress
    with warnings.catch_warnings(), run_progress(p, quiet=args.quiet) as progress:
        warnings.simplefilter("ignore", RunWarning)
        res = simulate(p, progress=progress)
    res.write_curve(out)
    plot_path = out.with_suffix(".png")
    if not args.no_plot:
        plot_curve(res.curve, p, plot_path)
    s = res.summary
    if not args.quiet:
        print(json.dumps({k: s[k] for k in ("pull_off_force", "pull_off_indent", "max_indent",
                                            "max_contact_radius", "n_steps", "n_solves",
                                            "solver_iters", "wall_time")}, indent=1))
        print(f"wrote {out}" + ("" if args.no_plot else f" and {plot_path}")
              + (f" and {res.fields_path}" if res.fields_path else ""), file=sys.stderr)
    if s["warnings"]:
        print(f"WARNING: {s['warnings']}", file=sys.stderr)
        return 3
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tfm", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="one loading-unloading curve (default: the paper's Fig. 3 case)",
                         description="Run one curve. Flags mirror the parameter names; fractions "
                                     "like 1/64 are accepted. Exit status 3 flags a suspect run "
                                     "(grid edge reached, solver not converged).")
    _add_param_flags(run)
    run.add_argument("-o", "--output", default="results/default/curve.parquet",
                     help="curve table (Parquet); the plot goes beside it as .png")
    run.add_argument("--no-plot", action="store_true")
    run.add_argument("-q", "--quiet", action="store_true")
    run.set_defaults(func=cmd_run)
    from .campaign.cli import register
    register(sub)
    register_views(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as exc:
        print(f"tfm: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
