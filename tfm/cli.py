"""Command line: `tfm run` (one curve), `tfm campaign ...` (grids of runs)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import warnings
from pathlib import Path

from . import __version__
from .params import ParameterError, Params
from .progress import say
from .viewcli import register as register_views


PARAM_HELP = {
    "spacing": "spring spacing Delta, e.g. 1/128",
    "alpha": "threshold exponent: F_th = k_th * A^alpha, in [-1, 3] (the paper: 0 to 1)",
    "k_th": "threshold parameter K_th (sets f_th to none)",
    "f_th": "explicit threshold force F_th",
    "radius": "radius R of the body",
    "shape": "sphere | paraboloid | flat_punch | height_map",
    "kernel": "boussinesq | local | neighbors",
    "self_term": "C_ii = self_term / sqrt(A), in (0, 1e6] (the paper's 3.8)",
    "neighbor_rings": "kernel=neighbors: keep 1/r for r <= m * spacing (with self_term 3.8, m >= 2 is "
                      "needed for a positive definite compliance; the default 1 goes with a larger self_term)",
    "c_w": "kernel=local: Winkler compliance, C_ii = c_w / A",
    "operator": "fft | direct | tree (kernels boussinesq and neighbors; the local kernel is a diagonal)",
    "theta": "operator=tree: opening angle (0, 1]",
    "layout": "square | hexagonal | jittered",
    "jitter": "layout=jittered: offsets in spacings, [0, 0.5)",
    "seed": "layout=jittered: random seed",
    "max_indent": "preload delta_max, or auto: (1.5 a_c)^2/R (a_c the JKR critical radius), or twice the Winkler depth "
                  "at F_th for the local and neighbors kernels",
    "step": "dilatation step",
    "snap_rule": "batch (the paper) | single",
    "tol": "relative residual of the contact solve",
    "max_iter": "CG iterations per solve (hitting it is flagged)",
    "max_rounds": "snap/enter rounds per step (hitting it is flagged)",
    "max_unload_steps": "cap on unloading steps (default 20 x loading steps + 1000; under force control plus twice the "
                        "continuum pull-off force in load steps)",
    "preconditioner": "auto | fft | stencil | diagonal | none",
    "extent": "grid half-width (default: from the Hertz radius at max_indent)",
    "extent_margin": "auto extent = margin * the Hertz radius sqrt(R max_indent) + 4 spacings (sqrt(2 R "
                     "max_indent) for the short-range kernels, R for a flat punch)",
    "control": "displacement (the paper) | force: load to max_load, lower the load until jump-off",
    "max_load": "control=force: peak compressive load (default: the Hertz load at max_indent)",
    "load_step": "control=force: load increment and decrement (default max_load / 100)",
    "snapshots": "field snapshots beside the table: none | events | K (every K-th step + events)",
    "hurst": "roughness: Hurst exponent H in (0, 1), PSD ~ q^(-2-2H)",
    "rms_slope": "roughness: spectral rms slope (0 = smooth)",
    "rms_height": "roughness: rms height (give it or rms_slope)",
    "short_cutoff": "roughness: shortest wavelength (default 4 spacings; >= 2)",
    "long_cutoff": "roughness: longest self-affine wavelength (default: the grid side)",
    "rolloff": "roughness: PSD at wavelengths longer than long_cutoff (q < q_L) = rolloff^2 C(q_L)",
    "roughness_seed": "roughness: random seed",
    "height_map": "shape=height_map: path to a .npy of heights (other formats: tfm[topography])",
    "map_pixel_size": "shape=height_map: pixel size (default: the file's, else spacing)",
    "height_map_hash": "sha256 of the map's heights (filled in; checked when given)",
    "threshold_disorder": "none | uniform | weibull: random F_th per spring around its mean",
    "disorder_width": "threshold disorder: std(F_th)/mean(F_th)",
    "disorder_seed": "threshold disorder: random seed",
    "units": "paper (nondimensional) | si (lengths in m, forces in N)",
    "youngs_modulus": "units=si: Young's modulus E (Pa)",
    "poisson_ratio": "units=si: Poisson ratio nu in (-1, 0.5]",
    "work_of_adhesion": "units=si: gamma (J/m^2); K_th from the paper's last equation",
    "k_th_coefficient": "units=si: c in F_max = c K_th^2 R: a number, paper (7.6), jkr (3 pi^2/4) or limit (the measured continuum limit for the self term; stored as its number)",
    "allow": "guards to override, comma-separated: coarse, step, tol, memory, cost (docs/physics.md)",
}


def _add_param_flags(parser: argparse.ArgumentParser) -> None:
    """One flag per parameter, named like the field with dashes (--k-th, --max-indent)."""
    from .units import COLUMN_UNITS

    dims = COLUMN_UNITS["paper"]["parameters"]
    unit = {"length": "L*; m with --units si", "force": "F*; N with --units si",
            "k_th": COLUMN_UNITS["paper"]["k_th"]}
    for f in dataclasses.fields(Params):       # no Params(): --help must not load Numba
        flag = "--" + f.name.replace("_", "-")
        default = f.default
        text = PARAM_HELP.get(f.name, "")
        if f.name in dims:                     # the unit, from the one table of units
            text += f" [{unit[dims[f.name]]}]"
        if "(default" not in text:            # a help text that says its default itself
            text += f" (default: {default!r})"
        parser.add_argument(flag, dest=f.name, default=None, metavar="VALUE", help=text)


def _params_from_args(args) -> Params:
    import warnings

    from .params import ParameterWarning

    values = {}
    for name in Params.field_names():
        raw = getattr(args, name)
        if raw is None:
            continue
        values[name] = raw                # "none" is read by Params.from_dict (params.NONE_WORDS)
    # the warnings are said before a refusal too: a map's size read in metres for want of a
    # unit is why its grid came out 64 million springs a side, and the error alone hid that
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ParameterWarning)
            return Params.from_dict(values)
    finally:
        for w in caught:
            print(f"tfm: warning: {w.message}", file=sys.stderr)


class OutputError(ParameterError):
    """An output path that cannot be written, or would replace data, found before the run."""


TABLE_SUFFIX = ".parquet"
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def default_output(p: Params) -> Path:
    """Where `tfm run` writes without -o: one folder per run id, so runs never clobber."""
    return Path("results") / "runs" / p.run_id / "curve.parquet"


def check_output(path: Path, what: str, suffixes: tuple[str, ...], overwrite: bool, create: bool) -> None:
    """Refuse, before any computation, an output that cannot be written or would replace
    a file without ``--overwrite``. ``create`` makes a missing folder (default paths only)."""
    if path.name.lower() in suffixes:       # ".parquet": a hidden name, no suffix for Path
        raise OutputError(f"{what}: {path} needs a file name before {path.name}, "
                          f"e.g. {path.with_name('curve' + path.name)}")
    if path.suffix.lower() not in suffixes:
        raise OutputError(f"{what}: {path} must end with {' or '.join(suffixes)}")
    if path.is_dir():
        raise OutputError(f"{what}: {path} is a folder; give a file name such as {path / ('curve' + suffixes[0])}")
    folder = path.parent
    if create:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"{what}: cannot create the folder {folder}: {exc.strerror}") from None
    if not folder.is_dir():
        raise OutputError(f"{what}: the folder {folder} does not exist (create it first)")
    if path.exists() and not overwrite:
        raise OutputError(f"{what}: {path} exists; pass --overwrite to replace it")
    probe = folder / f".{path.name}.{os.getpid()}.probe.tmp"
    try:
        probe.write_bytes(b"")
    except OSError as exc:
        raise OutputError(f"{what}: cannot write in {folder}: {exc.strerror}") from None
    finally:
        probe.unlink(missing_ok=True)


def _plan_outputs(args, p: Params) -> tuple[Path, Path | None]:
    out = Path(args.output) if args.output else default_output(p)
    check_output(out, "output", (TABLE_SUFFIX,), args.overwrite, create=not args.output)
    from .results import fields_path_for
    fields = fields_path_for(out)
    # the field snapshots stream beside the table; a run without them removes those of the
    # table it replaces (write_curve)
    if p.snapshots == "none" and fields.exists() and not args.overwrite:
        # not this run's output: a table's snapshots that would go stale beside this table
        raise OutputError(f"snapshots: {fields} exists, the field snapshots of another run at this path; this run "
                          "stores none and would remove them: pass --overwrite, or give another -o")
    check_output(fields, "snapshots", (".nc",), args.overwrite, create=False)
    if p.snapshots == "none" and fields.exists() and not args.quiet:
        print(f"tfm: note: --overwrite: {fields}, the snapshots of the table being replaced, will be removed",
              file=sys.stderr)
    if args.no_plot:
        if args.plot:
            raise OutputError("plot: give --plot FILE or --no-plot, not both")
        return out, None
    plot = Path(args.plot) if args.plot else out.with_suffix(".png")
    if plot.resolve() == out.resolve():
        raise OutputError(f"plot: {plot} is the table's own path; the plot needs a path of its own")
    check_output(plot, "plot", PLOT_SUFFIXES, args.overwrite, create=False)
    return out, plot


def _checkpoint_options(args, p: Params, out: Path) -> dict:
    """simulate()'s checkpoint arguments: by default a displacement-controlled run without
    snapshots saves its state beside the table every CHECKPOINT_EVERY seconds, and the same
    command continues a killed run. Asking for checkpoints where they cannot serve is refused."""
    path = checkpoint_path_for(out)
    if args.no_checkpoints and args.checkpoint_every is not None:
        raise ParameterError("checkpoint-every: give it or --no-checkpoints, not both")
    from .checkpoint import check_every, why_not
    from .config import CHECKPOINT_EVERY

    every = CHECKPOINT_EVERY if args.checkpoint_every is None else check_every(args.checkpoint_every,
                                                                                "checkpoint-every")
    reason = None if args.no_checkpoints else why_not(p)
    if args.checkpoint_every is not None and reason:
        raise ParameterError(f"checkpoint-every: {reason}")
    # with checkpoints or without: a run that replaced the table beside another run's saved
    # state left that state to be continued over its table, without a word
    _check_foreign_checkpoint(path, p, args.overwrite)
    if args.no_checkpoints or reason:
        return {}
    # kept until the table is written (_run_and_write): a stop while it is written would
    # otherwise find neither table nor checkpoint
    return {"checkpoint": path, "checkpoint_every": every, "replace_checkpoint": args.overwrite,
            "keep_checkpoint": True}


def _check_foreign_checkpoint(path: Path, p: Params, overwrite: bool) -> None:
    """The saved state of another run (a killed run with other parameters and the same
    -o), or a file that is no checkpoint, is not discarded without --overwrite: it was set
    aside and lost, without a word."""
    if overwrite:
        return
    from .checkpoint import Checkpoint

    ckpt = Checkpoint(path, p.run_id)
    what = ckpt.foreign()
    if what is None:
        return                            # none, or this run's: the run continues from it
    # a damaged file of this very run was told "rerun that run's command": the one just given
    advice = ("rerun that run's command to continue it, or pass --overwrite to discard it" if ckpt.saved_run_id()
              else "no run can continue from it (damaged, or not a checkpoint): pass --overwrite to discard "
                   "it, or move it away")
    raise OutputError(f"checkpoint: {path} holds {what}; {advice}")


def checkpoint_path_for(curve_path: Path) -> Path:
    """Where a `tfm run`'s checkpoint lives: beside its table, ``<stem>.checkpoint.npz``."""
    return curve_path.with_name(curve_path.stem + ".checkpoint.npz")


def _run_and_write(args, p: Params, notes, out: Path, plot: Path | None, ckpt: dict, worker):
    """`tfm run` from the announcement to the written table; the figure's ``worker`` (or
    None) gets the curve first and draws it while the table is written. Returns the
    result and the table's and figure's paths."""
    import warnings

    from .guards import direct_cost_note, estimate_memory
    from .progress import run_progress
    from .protocol import n_loading_steps
    from .results import fields_path_for
    from .checkpoint import CheckpointWarning
    from .simulate import RunWarning, simulate

    if not args.quiet:
        from .units import unit_suffixes
        m, N = unit_suffixes(p)
        body = f"map={Path(p.height_map).name}" if p.shape == "height_map" else f"R={p.radius:g}{m}"
        n_load = n_loading_steps(p)
        theta = f" theta={p.theta:g}" if p.operator == "tree" and p.kernel == "boussinesq" else ""
        operator = "" if p.kernel == "local" else f" operator={p.operator}"   # a diagonal: none used
        # a hexagonal or jittered run looked like a square-grid one
        layout = "" if p.layout == "square" else f" layout={p.layout}" + (
            f" jitter={p.jitter:g} seed={p.seed}" if p.layout == "jittered" else "")
        print(f"tfm run {p.run_id}: spacing={p.spacing:.6g}{m} F_th={p.threshold_force:.4g}{N} "
              f"{body} shape={p.shape}{layout} kernel={p.kernel}{operator}{theta} "
              f"max_indent={p.delta_max:.4g}{m} ({_steps_said(p, n_load, m)}), "
              f"memory ~{estimate_memory(p) / 2**20:.0f} MiB", file=sys.stderr)
        if p.shape == "height_map" and p.extent is None:
            from .surfaces import map_unused_note
            note = map_unused_note(p)     # information, not a flag: the edge flag covers the physics
            if note:
                print(f"tfm: note: {note}", file=sys.stderr)
    for note in notes:                    # stated before the run starts
        print(f"tfm: warning: {note}", file=sys.stderr)
    cost = direct_cost_note(p)
    if cost:                              # even with -q: hours may be at stake
        print(f"tfm: note: {cost}", file=sys.stderr)
    if p.snapshots != "none":
        from .snapshots import size_note
        size = size_note(p)
        if size:                          # even with -q: a full disk may be at stake
            print(f"tfm: note: {size}", file=sys.stderr)
    with warnings.catch_warnings(record=True) as caught, run_progress(p, quiet=args.quiet) as progress:
        warnings.simplefilter("ignore", RunWarning)     # the summary's warnings are printed at the end
        warnings.simplefilter("always", CheckpointWarning)
        res = simulate(p, progress=progress, fields_path=fields_path_for(out) if p.snapshots != "none" else None,
                       **ckpt)
    planned = out
    try:
        for w in caught:                      # a checkpoint set aside, say
            print(f"tfm: warning: {w.message}", file=sys.stderr)
        if res.provenance.get("resumed_at_step") and not args.quiet:
            print(f"continued from the checkpoint {ckpt['checkpoint']} at step {res.provenance['resumed_at_step']} "
                  "(the steps before were computed by the run that was stopped)", file=sys.stderr)
        out = _appeared(out, args, p.run_id)
        if plot is not None:                  # a default figure follows a diverted table
            plot = _appeared(out.with_suffix(".png") if args.plot is None else plot, args, p.run_id)
        if worker is not None and plot is not None:
            worker.send(res, plot)
        res.write_curve(out)
    except BaseException:
        # no table: the snapshots placed for it would only make the same command refuse
        # to start again (the run has no checkpoint; its message says it starts afresh)
        if res.fields_path is not None:
            Path(res.fields_path).unlink(missing_ok=True)
        raise
    args.written = out                    # for the message of an interruption from here on
    if ckpt:
        Path(ckpt["checkpoint"]).unlink(missing_ok=True)     # the table holds the run now
    elif out == planned:
        # nor does a saved state beside it that --overwrite discarded, or this run's own
        # from an earlier, checkpointed attempt (it would continue over the table)
        from .checkpoint import Checkpoint
        left = checkpoint_path_for(out)
        if left.exists() and (args.overwrite or Checkpoint(left, p.run_id).foreign() is None):
            left.unlink(missing_ok=True)
    return res, out, plot


def _appeared(path: Path | None, args, run_id: str) -> Path | None:
    """An output that another process wrote while this run computed (it was checked free
    before the run) is not replaced without --overwrite: this run's goes beside it, named
    by its run id."""
    if path is None or args.overwrite or not path.exists():
        return path
    alt = path.with_name(f"{path.stem}.{run_id}{path.suffix}")
    print(f"tfm: warning: {path} appeared while this run computed (another tfm run?); "
          f"writing this run's to {alt} instead", file=sys.stderr)
    return alt


def cmd_run(args) -> int:
    from .guards import check, kernel_check_key
    from .plot_worker import start_worker

    p = _params_from_args(args)
    notes = check(p)                      # refuses meaningless or oversized runs (exit 2)
    if kernel_check_key(p) is not None:   # a kernel that may be indefinite: before the header
        from .operators import check_record
        check_record(p)
    out, plot_path = _plan_outputs(args, p)
    ckpt = _checkpoint_options(args, p, out)
    args.checkpoint_path = ckpt.get("checkpoint")     # for the message if it is interrupted
    from .results import fields_path_for, remove_dead_temporaries
    remove_dead_temporaries(out, fields_path_for(out), checkpoint_path_for(out),
                            *([plot_path] if plot_path is not None else []))
    # the figure's worker imports and warms up while this process loads the engine and runs
    worker = start_worker(p) if plot_path is not None else None
    try:
        if getattr(args, "own_process", False):
            from .kernels import lean_start
            lean_start()
        res, out, plot_path = _run_and_write(args, p, notes, out, plot_path, ckpt, worker)
        failed = worker.finish() if worker is not None and plot_path is not None else None
    except BaseException:
        if worker is not None:
            worker.cancel()
        raise
    figure_lost = False
    if plot_path is not None:
        if failed:
            print(f"tfm: note: the figure's worker process failed ({failed}); drawing the figure here",
                  file=sys.stderr)
        if worker is None or failed:
            from .plots import write_curve_figure
            try:
                write_curve_figure(res.curve, p, plot_path)
            except OSError as exc:
                # a full disk: the table is written, and its summary and flags are still
                # worth printing (they were lost with the traceback); exit 1 below
                print(f"tfm: error: the figure {plot_path} could not be written ({exc.strerror or exc}); "
                      f"the table {out} is (tfm plot {out} draws it)", file=sys.stderr)
                plot_path, figure_lost = None, True
    s = res.summary
    if not args.quiet:
        jump = ("jump_off_force", "jump_off_indent", "jump_off_contact_radius") if p.control == "force" else ()
        shown = {k: s[k] for k in ("pull_off_force", "pull_off_indent", "max_indent", "max_contact_radius",
                                   *jump, "n_steps", "n_solves", "solver_iters", "wall_time", "force_unit",
                                   "length_unit")}
        # strict JSON (jq and others refuse NaN): a value that does not exist is null
        print(json.dumps({k: None if isinstance(v, float) and not math.isfinite(v) else v
                          for k, v in shown.items()},
                         indent=1, allow_nan=False))
        print(f"wrote {out}" + ("" if plot_path is None else f" and {plot_path}")
              + (f" and {res.fields_path}" if res.fields_path else ""), file=sys.stderr)
    # the notes were stated before the run (and open the summary's warnings): the rest only
    said = "; ".join(notes)
    rest = s["warnings"][len(said):].lstrip("; ") if said and s["warnings"].startswith(said) else s["warnings"]
    if rest:
        print(f"tfm: warning: {rest}", file=sys.stderr)
    return 1 if figure_lost else 3 if s["warnings"] else 0


def _steps_said(p, n_load: int, m: str) -> str:
    """The loading work in the run header. Under force control the flat moves at most
    ``step`` per solve: 100 load levels to a depth of 38 took 38,000 solves, not 100."""
    if p.control != "force":
        return f"{n_load} loading step{'' if n_load == 1 else 's'}"
    moves = math.ceil(p.delta_max / p.step - 1e-9)
    return (f"{n_load} load level{'' if n_load == 1 else 's'}; the flat moves at most step={p.step:g}{m} "
            f"a solve: {moves:,} or more solves to reach it")


# the subcommands, as `tfm --help` lists them (tests/test_cli.py checks this against the parser)
COMMANDS = ("run", "campaign", "plot", "show", "animate", "paper", "limit")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The `tfm` parser. With ``command`` "run" (the first word after `tfm`) the other
    subcommands are left out, with the same usage line: registering them imports the
    campaign code, 25 ms of a 1.1 s `tfm run` at 1/128 (2026-11-29)."""
    parser = argparse.ArgumentParser(prog="tfm", description=__doc__)
    parser.add_argument("--version", action="version", version=f"tfm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="one loading-unloading curve (default: the paper's Fig. 3 case)",
                         description="Run one curve. Flags mirror the parameter names; fractions "
                                     "like 1/64 are accepted. Outputs are checked before the run; "
                                     "nothing is replaced without --overwrite. Exit status 1: out of "
                                     "memory, or an output not written after the run; 2: bad "
                                     "input or output; 3: a suspect run (grid edge reached, solver "
                                     "not converged, rounds or unloading steps capped, fewer springs "
                                     "in contact than a disc of radius 2 spacings, a surface steeper "
                                     "than rms slope 1, auto preload capped, allowed past a guard, "
                                     "snapshots stopped early); 130: "
                                     "interrupted.")
    _add_param_flags(run)
    run.add_argument("-o", "--output", default=None, metavar="FILE.parquet",
                     help="curve table (default results/runs/<run_id>/curve.parquet)")
    run.add_argument("--plot", default=None, metavar="FILE.png",
                     help="the plot (.png, .pdf, .svg; default: beside the table, as .png)")
    run.add_argument("--overwrite", action="store_true", help="replace existing output files")
    run.add_argument("--no-plot", action="store_true", help="write the table only, no figure")
    run.add_argument("--checkpoint-every", type=float, default=None, metavar="SECONDS",
                     help="save the running curve's state this often beside the table "
                          "(<stem>.checkpoint.npz), so that the same command continues a killed run "
                          "(default 600 for displacement control without snapshots; 0 saves after every "
                          "step, which can make a run 20x slower; --no-checkpoints turns them off)")
    run.add_argument("--no-checkpoints", action="store_true", help="save no checkpoint")
    run.add_argument("-q", "--quiet", action="store_true",
                     help="no header, progress, summary or 'wrote' line: warnings, errors and the lines "
                          "of a stop signal (where the state is saved) only")
    run.set_defaults(func=cmd_run)
    if command == "run":
        parser.usage = f"tfm [-h] [--version] {{{','.join(COMMANDS)}}} ..."
        return parser
    from .campaign.cli import register
    register(sub)
    register_views(sub)
    from .paper.cli import register as register_paper   # tfm paper, tfm limit
    register_paper(sub)
    return parser


def exit_now(code: int) -> None:
    """End a `tfm run` process whose table and figure are written and closed: skip the
    interpreter's teardown of Numba, LLVM and pyarrow, 0.04 s of a 1.3 s run at 1/128
    (2026-11-24). Nothing of tfm's runs at exit; the output streams are flushed here."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


_PYTHON_FORMAT = warnings.formatwarning


def _format_warning(message, category, filename, lineno, line=None):
    """tfm's own warnings as a line a user reads ("spec.py:220: ParameterWarning: ...
    params = Params.from_dict(values, where=label)" was printed for a campaign's)."""
    if category.__module__.split(".")[0] == "tfm":
        return f"tfm: warning: {message}\n"
    return _PYTHON_FORMAT(message, category, filename, lineno, line)


def attach_negative_values(argv: list[str]) -> list[str]:
    """``--flag -1/64`` as ``--flag=-1/64``: argparse takes a word that starts with '-' for
    an option unless it looks like a plain negative number, so a negative fraction or
    exponent got "expected one argument" instead of the parameter's own range message. No
    option of tfm starts with a digit or a dot."""
    out = []
    for word in argv:
        if (out and out[-1].startswith("--") and "=" not in out[-1] and len(word) > 1
                and word[0] == "-" and (word[1].isdigit() or word[1] == ".")):
            out[-1] = f"{out[-1]}={word}"
        else:
            out.append(word)
    return out


THREAD_VARIABLES = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")


def check_thread_settings() -> None:
    """A thread count that is not a whole number >= 1: Numba's 0 or -1 raised a traceback
    mid-import, and OMP_NUM_THREADS=abc surfaced as "internal error in the DUCC0 backend"
    from the first FFT. Refused up front, naming the variable (empty counts as unset)."""
    for name in THREAD_VARIABLES:
        value = os.environ.get(name, "").strip()
        if value and not (value.isdigit() and int(value) >= 1):
            raise ParameterError(f"{name}: the environment variable must be a whole number >= 1 (threads), "
                                 f"got {os.environ[name]!r}")


def main(argv=None) -> int:
    """The `tfm` command; ``argv`` None: the process's own arguments, and the process ends
    after it."""
    import gc

    if argv is None and "numpy" not in sys.modules:
        # OpenBLAS starts a thread per core as NumPy, and again as SciPy (which Numba
        # imports), load it, and each thread spins about 0.1 s before it sleeps: 0.3 s of
        # CPU taken from the figure's worker in a 1.5 s `tfm run` at 1/128 on 2 cores, for
        # no work (2026-11-24). tfm's dense algebra is small: the largest, an eigenvalue
        # check of 1200 springs, took 0.10 s on one thread against 0.08 s on two. Child
        # processes (figure, campaign workers) inherit the setting; a user's value stands.
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    words = attach_negative_values(sys.argv[1:] if argv is None else argv)
    args = build_parser(words[0] if words else None).parse_args(words)
    if argv is None:
        warnings.formatwarning = _format_warning
    if argv is None and args.func is cmd_run:
        # One curve in a process of its own. Importing Numba, pandas and pyarrow makes
        # millions of objects, and the cyclic collector's passes over them took 0.25 s of a
        # 1.9 s `tfm run` at 1/128, while a curve leaves almost no cyclic garbage (406
        # objects for a whole 1/64 curve, none for a 1/128 one after it; 2026-11-24).
        gc.disable()
        args.own_process = True           # nothing but tfm's kernels compiled here (cmd_run)
    try:
        check_thread_settings()
        code = args.func(args)
        if argv is None and args.func is cmd_run:
            exit_now(code)
        return code
    except ParameterError as exc:
        print(f"tfm: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_status", 2)     # 1: an output lost after computing
    except MemoryError:
        # a traceback from deep inside NumPy said nothing a user could act on
        say("tfm: error: out of memory: the run needed more than this process could get (the estimate "
            "before a run is in its first line). Coarsen the spacing or shrink extent")
        return 1
    except BrokenPipeError:
        # the reader of the output went away (`tfm campaign list | head`): no traceback,
        # and nothing more written to the closed pipe at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13
    except KeyboardInterrupt:
        if args.func is not cmd_run:
            raise
        # no traceback for a Ctrl-C; say what survives (the table is written only at the end)
        written = getattr(args, "written", None)
        if written is not None:
            say(f"tfm: interrupted: the table {written} was written, the figure was not "
                f"(tfm plot {written} draws it)")
            return 130
        ckpt = getattr(args, "checkpoint_path", False)
        if ckpt is False:                 # stopped before its outputs were planned
            kept = ""
        elif ckpt is None:
            kept = ("; this run keeps no checkpoint (force control, field snapshots and --no-checkpoints "
                    "have none): the same command starts it again")
        elif ckpt.exists():
            kept = f"; its checkpoint {ckpt} lets the same command continue"
        else:
            kept = "; it was stopped before its first step was saved"
        say(f"tfm: interrupted: no table written{kept}")
        return 130
    finally:
        if argv is None:
            # Python's last collection at exit walks every object again: 0.3 s of a 2.4 s
            # `tfm run` at 1/128. Frozen objects are skipped (the process still frees them
            # all; its files are closed by then).
            gc.freeze()


if __name__ == "__main__":
    sys.exit(main())
