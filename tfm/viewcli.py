"""Command line views of stored runs: `tfm plot`, `tfm show`, `tfm animate`.

RUN is a curve table (``curve.parquet``, ``results/<campaign>/runs/<id>.parquet``), a
folder holding one (``results/default``), or a campaign run id (searched under
``results/*/runs/``). Nothing is re-run: the figures come from the stored curve and the
stored field snapshots (``<stem>.fields.nc``, see tfm.snapshots).
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import warnings
from pathlib import Path

EVENT_NAMES = ("pull_off", "max_load", "first_snap", "last_contact")


class ViewError(Exception):
    """A stored run cannot be shown as asked (missing file, step not stored, ...)."""


def register(sub) -> None:
    plot = sub.add_parser("plot", help="redraw the figure of a stored curve",
                          description="Redraw the force-indentation figure of a stored run.")
    plot.add_argument("run", help="curve .parquet, a folder with one, or a campaign run id")
    plot.add_argument("-o", "--output", help="PNG/PDF/SVG path (default: beside the curve, .png)")
    _overwrite_flag(plot)
    plot.set_defaults(func=cmd_plot)

    show = sub.add_parser("show", help="contact map of a stored field snapshot",
                          description="Draw the contact map of one stored snapshot: spring force "
                                      "(diverging colours, F_th marked), released springs, contact "
                                      "line, beside the force-indentation curve.")
    show.add_argument("run", help="curve .parquet, a folder with one, or a campaign run id")
    show.add_argument("--step", default="pull_off", action=_Once,
                      help=f"a stored step number, or an event: {', '.join(EVENT_NAMES)} (default pull_off)")
    show.add_argument("-o", "--output", help="image path (default: <stem>.step<k>.png beside the curve)")
    _overwrite_flag(show)
    show.set_defaults(func=cmd_show)

    anim = sub.add_parser("animate", help="GIF/MP4 of the unloading from stored snapshots",
                          description="Animate the unloading from the stored field snapshots: the "
                                      "contact map beside the force-indentation curve, with a marker "
                                      "on the curve. Made for a run with snapshots = k (every k-th "
                                      "step); one with snapshots = events gives a frame per event.")
    anim.add_argument("run", help="curve .parquet, a folder with one, or a campaign run id")
    anim.add_argument("-o", "--output", help="a .gif (Pillow) or .mp4 (needs ffmpeg); default <stem>.gif")
    anim.add_argument("--fps", type=float, default=DEFAULT_FPS,
                      help=f"frames per second (default {DEFAULT_FPS:g}; 0.01 to {GIF_MAX_FPS:g} for a GIF, which viewers "
                           "play at 10 fps above that; at least 0.01 for MP4)")
    anim.add_argument("--all-phases", action="store_true", help="loading too, not only the unloading")
    anim.add_argument("--max-frames", type=int, default=DEFAULT_MAX_FRAMES,
                      help=f"at most this many frames (default {DEFAULT_MAX_FRAMES}): of more stored snapshots every "
                           "k-th is used, with the first, the last and the events; 0: all")
    _overwrite_flag(anim)
    anim.set_defaults(func=cmd_animate)


class _Once(argparse.Action):
    """An option given at most once: a second --step replaced the first without a word."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, f"_{self.dest}_given", False):
            parser.error(f"{option_string} given twice ({getattr(namespace, self.dest)!r} and {values!r}); "
                         "one view draws one step")
        setattr(namespace, f"_{self.dest}_given", True)
        setattr(namespace, self.dest, values)


def _overwrite_flag(parser) -> None:
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing file given with -o (the default beside the run is "
                             "the run's own figure, and is always replaced)")


# ---- finding and loading a stored run -------------------------------------------------
def resolve_run(arg: str, results_dir: str | Path = "results") -> Path:
    p = Path(arg)
    if p.is_file():
        return p
    if p.is_dir():
        if (p / "curve.parquet").is_file():
            return p / "curve.parquet"
        found = sorted(q for q in p.glob("*.parquet") if not q.name.startswith("."))
        if len(found) == 1:
            return found[0]
        if (p / "campaign.json").is_file() and (p / "runs").is_dir():
            # a campaign's folder: its tables hold many runs, and naming one was refused too
            raise ViewError(f"{p}: a campaign's folder; name one of its runs: {p / 'runs'}/<run_id>.parquet, "
                            "or the run id alone (run ids: the run_id column of summary.parquet)")
        raise ViewError(f"{p}: expected one curve table in the folder, found {len(found)}; name the file")
    if re.fullmatch(r"[0-9a-f]{8,16}", p.name):
        found = sorted(Path(results_dir).glob(f"*/runs/{p.name}*.parquet"))
        if len(found) == 1:
            return found[0]
        if found:
            raise ViewError(f"run id {p.name}: several runs match: {', '.join(map(str, found))}")
    raise ViewError(f"{arg}: no such curve table, folder or run id (under {results_dir}/*/runs/)")


# what the views draw from a curve table
VIEW_COLUMNS = ("step", "phase", "indent", "force", "contact_radius", "n_contact")


def load_run(path: Path):
    """The curve, the parameter record (None if it cannot be rebuilt) and the fields path.
    Refuses a file that is not one run's curve table (ViewError)."""
    import pyarrow

    path = Path(path)

    from .params import ParameterError, Params
    from .results import fields_path_for, read_checked, read_metadata

    try:
        curve = read_checked(path)
        meta = read_metadata(path)
    except (pyarrow.ArrowException, OSError) as exc:
        why = getattr(exc, "strerror", None) or "corrupt, truncated or another format"
        raise ViewError(f"{path}: not a readable Parquet table ({why}); give a curve table "
                        "written by tfm run or by a campaign") from None
    _check_one_curve(path, curve, meta)
    flags = (meta.get("summary") or {}).get("warnings")
    if flags:                            # a figure of a flagged run looked like any other
        print(f"tfm: note: {path.name} is a flagged run: {flags}", file=sys.stderr)
    try:
        with warnings.catch_warnings():          # a stored record is complete and was valid
            warnings.simplefilter("ignore")
            params = Params.from_dict(meta["params"]) if "params" in meta else None
    except (ParameterError, TypeError) as exc:
        # stored by another tfm version, or its height map has moved: say so, draw anyway
        units = meta.get("units") or {}
        si = (f"; its lengths are in {units.get('length')} and its forces in {units.get('force')}, which the "
              "axes do not say" if units.get("system") == "si" else "")
        print(f"tfm: note: {path}: its parameter record does not rebuild ({exc}); drawn without "
              f"the caption and the analytical reference{si}", file=sys.stderr)
        params = None
    # the name the table recorded, else the table's own <stem>.fields.nc (a table renamed
    # with its snapshots); _need_fields checks that they are this run's
    # (a path that does not exist: the table names snapshots that are gone)
    named = path.parent / meta["fields"] if meta.get("fields") else None
    found = next((f for f in (named, fields_path_for(path)) if f is not None and f.exists()), None)
    return curve, params, found or named


def _check_one_curve(path: Path, curve, meta: dict) -> None:
    """A campaign's joined curves (a run_id column) and its summary hold no single curve:
    drawn as one they made one line through all runs, or a KeyError."""
    runs = path.parent / "runs"
    where = (f"one run's table, {runs}/<run_id>.parquet, or its run id"
             if runs.is_dir() else "one run's curve table (a campaign keeps them in runs/<run_id>.parquet)")
    missing = [c for c in VIEW_COLUMNS if c not in curve.columns]
    if missing:
        kind = "a campaign's table" if "campaign" in meta else "a table"
        raise ViewError(f"{path} is {kind} without the curve columns {', '.join(missing)}; give {where}")
    if "run_id" in curve.columns and curve["run_id"].nunique() > 1:
        raise ViewError(f"{path} holds the curves of {curve['run_id'].nunique()} runs (a campaign's "
                        f"curves table); give {where}")


def _need_fields(path, fields, params):
    if fields is not None and not fields.exists():
        from .results import fields_path_for
        looked = list(dict.fromkeys([fields.name, fields_path_for(path).name]))
        raise ViewError(f"{path}: the run stored field snapshots, but they are not beside the table (looked "
                        f"for {' and '.join(looked)}): moved or deleted? Put the file back as "
                        f"{fields_path_for(path)}, or rerun the run with --snapshots")
    if fields is None:
        raise ViewError(f"{path}: the run stored no field snapshots; rerun it with --snapshots events "
                        "(or --snapshots K for every K-th step)")
    from .results import fields_path_for, read_metadata
    from .snapshots import Fields
    from .units import force_scale, to_paper

    # Another run's snapshots left beside the table (a rerun to the same -o without any)
    # would be drawn with this curve. An SI run's file written before the writer recorded
    # the SI record holds its paper-units twin's run id (tfm.units.to_paper): accept both.
    table_id = read_metadata(path).get("run_id")
    ours = {table_id} | ({params.run_id, to_paper(params).run_id} if params is not None else set())
    ours.discard(None)
    # the recorded name first, then the table's own <stem>.fields.nc: a table renamed with
    # its snapshots, whose recorded name now holds a newer run's, was refused as stale
    own = fields_path_for(path)
    why = None
    for candidate in [fields] + ([own] if own != fields and own.exists() else []):
        try:
            out = Fields(candidate)
        except (OSError, KeyError) as exc:
            # a damaged file under the recorded name must not hide the table's own good one
            why = why or f"{candidate}: not a readable field snapshots file ({exc})"
            continue
        theirs = out.attrs.get("run_id")
        theirs = theirs.decode() if isinstance(theirs, bytes) else theirs
        if not ours or theirs in ours:
            if params is not None:
                out.use_force_scale(force_scale(params))      # forces in the table's units (SI: N)
            return out
        if why is None:
            held = f"the snapshots of run {theirs}" if theirs else "snapshots of no recorded run"
            why = (f"{candidate} holds {held}, not of run {table_id or params.run_id} in {path}: "
                   "stale, from an earlier run; rerun this one with snapshots on (--snapshots events or a step count)")
    raise ViewError(why)


# why a run has no snapshot of an event (tfm.snapshots.SnapshotWriter.observe)
EVENT_ABSENT = {"pull_off": "the run never pulled (no step under tension: no adhesion)",
                "first_snap": "no spring snapped while unloading",
                "last_contact": "unloading stopped with springs still in contact",
                "max_load": "no step was recorded"}


def snapshots_cut_short(fields, unloading: bool = True) -> str | None:
    """Why the run's snapshots end early, from the file: the disk guard stopped them
    (tfm.snapshots), or (``unloading``, from the stored summary) max_unload_steps stopped
    the unloading."""
    import json

    stopped = fields.attrs.get("stopped_at_step")
    if stopped is not None:
        return f"field snapshots stopped at step {int(stopped)} (too little disk space), so the later steps have none"
    try:
        summary = json.loads(fields.attrs.get("summary") or "{}")
    except (TypeError, ValueError):
        return None
    if unloading and summary.get("unload_complete") is False:
        return ("unloading stopped at max_unload_steps with springs still in contact, before the events "
                "after it (raise max_unload_steps)")
    return None


def _event_absent(fields, event: str) -> str:
    """Why a run has no snapshot of ``event``: the snapshots or the unloading were cut
    short (show blamed "no adhesion" on a run that max_unload_steps stopped), else the
    event's own reason."""
    return snapshots_cut_short(fields, unloading=event != "max_load") or EVENT_ABSENT[event]


def pick_step(fields, step: str) -> int:
    if step.strip().lower() in EVENT_NAMES:      # read like every other named value
        step = step.strip().lower()
        k = fields.event_step(step)
        if k is None:
            stored = [f"{e} (step {fields.event_step(e)})" for e in EVENT_NAMES if fields.event_step(e) is not None]
            raise ViewError(f"{fields.path}: no {step} snapshot: {_event_absent(fields, step)}; "
                            + (f"stored events: {', '.join(stored)}; pick one with --step"
                               if stored else "no event snapshot stored"))
        return k
    try:
        k = int(step)
    except ValueError:
        raise ViewError(f"--step: expected a step number or one of {', '.join(EVENT_NAMES)}, got {step!r}") from None
    if k not in set(fields.steps.tolist()):
        near = fields.steps[abs(fields.steps - k).argsort()[:5]]
        raise ViewError(f"--step {k}: not stored; nearest stored steps: {', '.join(map(str, sorted(near)))}")
    return k


# ---- the commands ----------------------------------------------------------------
def cmd_plot(args) -> int:
    return _guard(_plot, args)


def cmd_show(args) -> int:
    return _guard(_show, args)


def cmd_animate(args) -> int:
    return _guard(_animate, args)


def _guard(fn, args) -> int:
    try:
        out = fn(args)
    except ViewError as exc:
        print(f"tfm: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        # after the checks: a snapshot file damaged inside, an output that cannot be
        # replaced (read-only, immutable), a full disk; an earlier output is left whole
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"tfm: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}", file=sys.stderr)
    return 0


def _output(args, default: Path, suffixes: tuple[str, ...]) -> Path:
    """-o (or the default beside the run) checked before anything is drawn: a suffix that
    no writer takes failed after the drawing, with a traceback. A file given with -o is
    not replaced without --overwrite (it may be anything); the default is the run's own
    figure, drawn again."""
    from .cli import OutputError, check_output

    out = Path(args.output) if args.output else default
    try:
        # a default output in a folder that cannot be written was reported as "-o: ..."
        check_output(out, "-o" if args.output else f"{out.name} (the default; -o puts it elsewhere)", suffixes,
                     overwrite=args.overwrite or not args.output, create=not args.output)
    except OutputError as exc:
        raise ViewError(str(exc)) from None
    return out


def _plot(args) -> Path:
    from .cli import PLOT_SUFFIXES
    from .plots import write_curve_figure

    path = resolve_run(args.run)
    out = _output(args, path.with_suffix(".png"), PLOT_SUFFIXES)
    curve, params, _ = load_run(path)
    return write_curve_figure(curve, params, out)


def _show(args) -> Path:
    from .cli import PLOT_SUFFIXES
    from .plots import plot_contact_map

    path = resolve_run(args.run)
    curve, params, fpath = load_run(path)
    fields = _need_fields(path, fpath, params)
    k = pick_step(fields, args.step)
    out = _output(args, path.with_name(f"{path.stem}.step{k}.png"), PLOT_SUFFIXES)
    plot_contact_map(fields, fields.snapshot(k), curve, params, out)
    return out


def _animate(args) -> Path:
    path = resolve_run(args.run)
    out = _output(args, path.with_suffix(".gif"), ANIMATION_SUFFIXES)
    check_fps(args.fps, out)
    check_max_frames(args.max_frames)
    curve, params, fpath = load_run(path)
    fields = _need_fields(path, fpath, params)
    n = animate(fields, curve, params, out, fps=args.fps, unload_only=not args.all_phases,
                max_frames=args.max_frames)
    stored = frame_steps(fields, curve, not args.all_phases)
    if n < len(stored):
        from .snapshots import every
        _, k = frame_plan(stored, args.max_frames, keep=event_steps(fields))
        used = (f"{every(k, 'one')} is used, with the first, the last and the events" if k else
                "only the first, the last and the events (as many as fit) are used")
        print(f"tfm: note: {len(stored)} snapshots to animate, more than --max-frames {args.max_frames}: "
              f"{used} (--max-frames 0 animates all)", file=sys.stderr)
    if out.suffix.lower() == ".gif":
        played = 100.0 / gif_centiseconds(args.fps)
        if abs(played - args.fps) > 0.01 * args.fps:
            print(f"tfm: note: a GIF stores frame times in hundredths of a second: --fps {args.fps:g} plays at "
                  f"{played:.3g} fps", file=sys.stderr)
    events = " (the run stored snapshots at its events only; --snapshots K stores every K-th step)" \
        if params is not None and params.snapshots == "events" else ""
    print(f"{n} frames{events}", file=sys.stderr)
    return out


# the events an animation keeps when thinned, most wanted first (tfm.snapshots.EVENTS)
FRAME_EVENTS = ("pull_off", "first_snap", "last_contact", "max_load")


def event_steps(fields) -> list[int]:
    """The steps of the run's events that have a snapshot, in FRAME_EVENTS' order."""
    steps = (fields.event_step(e) for e in FRAME_EVENTS)
    return [s for s in steps if s is not None]


def frame_steps(fields, curve, unload_only: bool = True) -> list[int]:
    """The stored steps to animate, in order: the unloading ones (with the last loading
    step as the first frame, when stored), or all."""
    steps = fields.steps.tolist()
    if not unload_only:
        return steps
    phase = dict(zip(curve["step"].tolist(), curve["phase"].tolist()))
    unload = [s for s in steps if phase.get(s) == "unload"]
    load = [s for s in steps if phase.get(s) == "load"]
    return ([load[-1]] if load else []) + unload


def frame_plan(steps: list[int], max_frames: int, keep=()) -> tuple[list[int], int]:
    """The frames of at most ``max_frames`` (all if 0) from ``steps``: the first, the
    last, the events in ``keep`` (in their order of priority, as many as fit) and every
    k-th step, k the smallest that stays within ``max_frames``; returns (frames, k), k = 0
    when the first, the last and the events fill it. The events used to come on top: 13
    frames for --max-frames 10 (a user's hunt). A GIF of 1257 frames took four minutes and
    900 MB of memory (another)."""
    n = len(steps)
    if not max_frames or n <= max_frames:
        return list(steps), 1
    inside = set(steps)
    must = list(dict.fromkeys([steps[0], steps[-1]] + [s for s in keep if s in inside]))
    if len(must) >= max_frames:
        chosen = set(must[:max_frames])
        return [s for s in steps if s in chosen], 0
    must = set(must)
    k = -(-n // max_frames)
    while True:                 # k = n leaves only the first, so this ends
        frames = [s for i, s in enumerate(steps) if i % k == 0 or s in must]
        if len(frames) <= max_frames:
            return frames, k
        k += 1


ANIMATION_SUFFIXES = (".gif", ".mp4")
DEFAULT_MAX_FRAMES = 300        # 30 s at the default 10 fps
# 10 cs a frame: a GIF plays it exactly (the former 8 fps played at 8.33, with a note on
# every default run)
DEFAULT_FPS = 10.0

# A GIF stores frame durations in whole centiseconds (gif_centiseconds), and browsers and
# most viewers play a frame of 0 or 1 cs at 10 cs: above 50 fps (2 cs) a GIF played at
# 10 fps, without a word; the longest it can store is 655.35 s. Below 0.01 fps (100 s a
# frame) nothing is an animation.
GIF_MAX_FPS = 50.0
MIN_FPS = 0.01


def check_max_frames(max_frames) -> None:
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 0:
        raise ViewError(f"--max-frames: a whole number of frames >= 0 (0: every stored snapshot), got {max_frames!r}")
    if max_frames == 1:
        raise ViewError("--max-frames: 1 frame is no animation; give 2 or more (0: every stored snapshot), "
                        "or draw one step with tfm show")


def check_fps(fps: float, out) -> None:
    import math

    gif = Path(out).suffix.lower() == ".gif"
    if not (fps >= MIN_FPS and math.isfinite(fps)) or (gif and fps > GIF_MAX_FPS):
        allowed = f"{MIN_FPS:g} <= fps <= {GIF_MAX_FPS:g} for a GIF" if gif else f"a finite fps >= {MIN_FPS:g}"
        faster = (" (viewers play faster GIF frames at 10 fps; an .mp4 takes any rate)"
                  if gif and math.isfinite(fps) and fps > GIF_MAX_FPS else "")
        raise ViewError(f"--fps {fps:g}: expected {allowed}{faster}")


def animate(fields, curve, params, out, fps: float = DEFAULT_FPS, unload_only: bool = True, dpi: int = 110,
            max_frames: int = 0) -> int:
    """Write a GIF (Pillow) or MP4 (ffmpeg) of the stored snapshots; returns the frame
    count. ``max_frames`` > 0: at most that many (frame_plan)."""
    import shutil

    out = Path(out)
    if out.suffix.lower() not in ANIMATION_SUFFIXES:
        raise ViewError(f"-o {out}: the animation is written as .gif or .mp4")
    check_fps(fps, out)
    check_max_frames(max_frames)
    if out.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
        raise ViewError("MP4 needs ffmpeg on the PATH; write a .gif instead (-o anim.gif)")
    steps = frame_steps(fields, curve, unload_only)
    if not steps:
        raise ViewError(f"{fields.path}: no snapshots to animate")
    if unload_only and len(steps) == 1:
        # the snapshots (or the run) stopped before unloading: a GIF of one loading frame
        # was written without a word
        why = snapshots_cut_short(fields) or "the run stored none while unloading"
        raise ViewError(f"{fields.path}: no unloading snapshot to animate: {why}; --all-phases animates "
                        "the loading snapshots")
    steps, _ = frame_plan(steps, max_frames, keep=event_steps(fields))
    from .results import through_temporary

    # through a temporary file beside it: a failed write leaves an earlier animation whole
    out.parent.mkdir(parents=True, exist_ok=True)
    with through_temporary(out, keep_suffix=True) as tmp:
        _write_animation(fields, curve, params, tmp, fps, steps, dpi)
    return len(steps)


def _write_animation(fields, curve, params, out, fps, steps, dpi) -> None:
    import numpy as np
    from matplotlib import rc_context
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from . import plots

    # one colour scale for every frame: the most compressive force shown, and F_th
    fmin = 0.0
    for k in steps:
        snap = fields.snapshot(k)
        con = np.asarray(snap["state"]) == 1
        if con.any():
            fmin = min(fmin, float(np.asarray(snap["F"])[con].min()))
    vlim = plots.force_limits(float(np.nanmax(fields.f_th)), fmin)
    frames = []
    with rc_context(plots.STYLE):
        fig, (ax_map, ax_curve) = plots.map_figure(params)
        fig.set_dpi(dpi)
        canvas = FigureCanvasAgg(fig)
        marker = plots.draw_curve_marker_panel(ax_curve, curve, params)
        head = plots.wrap_caption(plots.run_caption(params), fig.get_figwidth()) + "\n" if params is not None else ""
        title = fig.suptitle(head, fontsize=8)
        incomplete = plots.unload_incomplete(curve)
        cmap = None
        writer = _mp4_writer(fig, out, fps, dpi) if out.suffix.lower() == ".mp4" else None
        background = None
        try:
            for k in steps:
                snap = fields.snapshot(k)
                if cmap is None:
                    cmap = plots.ContactMap(ax_map, fields, snap, vlim=vlim, params=params)
                    plots.tidy_ticks(ax_map)
                    plots.fold_offsets(fig)          # the axes are fixed: as tfm show draws them
                else:
                    cmap.update(snap)
                title.set_text(head + plots.snapshot_title(snap, params, incomplete))
                marker.set_data([-snap["d"]], [snap["force"]])
                if writer is not None:
                    writer.grab_frame()
                    continue
                # blitting: the axes, ticks and curves are drawn once; each frame redraws
                # only what moves (map, contact line, marker, title) over that background
                moving = cmap.artists() + [marker, title]
                for artist in moving:
                    artist.set_animated(True)
                if background is None:
                    canvas.draw()
                    fig.set_layout_engine("none")      # the first frame's layout holds for all
                    background = canvas.copy_from_bbox(fig.bbox)
                canvas.restore_region(background)
                for artist in moving:
                    fig.draw_artist(artist)
                frames.append(_to_palette(canvas, frames[0] if frames else None))
            if writer is not None:
                writer.finish()
        except (BrokenPipeError, subprocess.CalledProcessError) as exc:
            # ffmpeg ended early (an encoder it lacks, a bad build): its broken pipe was
            # taken for tfm's own stdout's, and the command ended with status 141, silent
            raise ViewError(f"ffmpeg failed to write {out.suffix} ({_ffmpeg_error(writer, exc)}); "
                            "write a .gif instead (-o anim.gif)") from None
    if frames:
        frames[0].save(out, save_all=True, append_images=frames[1:], duration=10 * gif_centiseconds(fps), loop=0,
                       format="GIF")


def gif_centiseconds(fps: float) -> int:
    """A GIF frame's time: whole hundredths of a second, the nearest to 1/fps (int(1000 / fps)
    ms was cut to 12 cs at 8 fps, 8.33 fps played)."""
    return max(1, round(100.0 / fps))


def _ffmpeg_error(writer, exc) -> str:
    """ffmpeg's last line on stderr, else what failed."""
    proc = getattr(writer, "_proc", None)
    err = getattr(exc, "stderr", None)
    if not err and proc is not None:
        try:
            proc.kill()
            err = proc.communicate(timeout=10)[1]
        except (OSError, ValueError, subprocess.SubprocessError):
            err = None
    if isinstance(err, bytes):
        err = err.decode(errors="replace")
    lines = (err or "").strip().splitlines()
    return lines[-1] if lines else type(exc).__name__


def _to_palette(canvas, first=None):
    """The drawn frame as a palette image (1 byte per pixel: frames stay small in memory),
    in the palette of the ``first`` frame when given: one palette for the whole animation,
    so a force has one colour in every frame (a palette per frame moved the colour bar's
    colours by up to 82/255 between frames). The first frame holds the whole colour bar."""
    from PIL import Image

    img = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
    if first is None:
        return img.quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    return img.quantize(palette=first, dither=Image.Dither.NONE)


def _mp4_writer(fig, out, fps, dpi):
    from matplotlib.animation import FFMpegWriter

    writer = FFMpegWriter(fps=fps)
    writer.setup(fig, str(out), dpi=dpi)
    return writer


def main(argv=None) -> int:      # python -m tfm.viewcli plot RUN (same as tfm plot RUN)
    parser = argparse.ArgumentParser(prog="tfm")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
