"""One run: a parameter record in, a curve and a summary out."""
from __future__ import annotations

import dataclasses
import difflib
import os
import warnings
from collections.abc import Mapping
from pathlib import Path

from .checkpoint import CHECKPOINT_EVERY, Checkpoint, StopRequest, why_not
from .geometry import heights, make_layout
from .guards import check
from .operators import check_positive_definite, grid_symbol, kernel_spec, make_operator, make_preconditioner
from .params import _DEFAULTS, ParameterError, Params
from .results import RunResult, curve_columns, provenance, summarize
from .solver import Problem
from .threshold import threshold_forces
from .units import force_scale, to_paper, to_si_curve, to_si_summary, unit_labels


class RunWarning(UserWarning):
    """A run finished but its numbers are suspect (edge reached, no convergence, ...)."""


def build_problem(p: Params) -> tuple[Problem, object]:
    layout = make_layout(p)
    spec = kernel_spec(p, layout)
    symbol = grid_symbol(spec, layout) if layout.shape is not None else None
    check_positive_definite(p, spec, layout, symbol)
    op = make_operator(p, spec, layout, symbol)
    pre = make_preconditioner(p, spec, layout, symbol, op)
    # A height map is a finite body whose edge is the map's: contact there is physical,
    # not a sign of a too-small grid; where the grid crops the map, it is that sign.
    edge = layout.edge
    if p.shape == "height_map":
        from .surfaces import map_cropped_edge
        edge = map_cropped_edge(p, layout.x, layout.y, layout.edge)
    prob = Problem(x0=heights(p, layout), f_th=threshold_forces(p, layout.area), area=layout.area, edge=edge,
                   operator=op, precond=pre, tol=p.tol, max_iter=p.max_iter,
                   max_rounds=p.max_rounds, snap_rule=p.snap_rule)
    return prob, layout


# simulate's keywords besides the parameters
KEYWORDS = ("progress", "fields_path", "checkpoint", "checkpoint_every", "keep_checkpoint",
            "replace_checkpoint")


def simulate(p: Params | None = None, *, progress=None, fields_path=None, checkpoint=None,
             checkpoint_every: float = CHECKPOINT_EVERY, keep_checkpoint: bool = False,
             replace_checkpoint: bool = False,
             **overrides) -> RunResult:
    """Run the loading protocol of ``p.control`` (tfm.protocol). ``simulate(spacing=1/64,
    k_th=0.02)`` and ``simulate(Params(...))`` both work. Suspect results carry flags and warn.

    ``progress(record)`` is called after every step with its tfm.solver.StepRecord (step,
    phase, d, force, contact_area, n_contact, ...; the run's units: newtons and metres in
    an SI run; force = -sum(F), compressive positive, as in the curve table). With ``p.snapshots`` other than
    "none" the field snapshots stream to ``fields_path`` (NetCDF4, ``.nc``, tfm.snapshots),
    which ``RunResult.write_curve`` copies beside the curve; without a path they go to a
    temporary file that it moves there, and that is removed when the process exits if no
    write_curve has (give ``fields_path`` to keep the snapshots without a table).

    ``checkpoint`` (a file path, displacement control without snapshots): the run's state
    is saved there every ``checkpoint_every`` seconds, a saved state of this run is
    continued from (same curve, bit for bit), and the file is removed when the run ends,
    unless ``keep_checkpoint``: then the caller removes it once it has stored the result (a
    campaign worker's result may yet be lost on its way to the campaign process). A file
    there that is not this run's saved state (another run's, or no checkpoint at all) is
    refused, and left alone, unless ``replace_checkpoint``: then it is not used, and the
    run's own saves overwrite it (no copy is kept). This run's state saved by another
    version of tfm is always set aside with a warning (it cannot promise the same numbers)."""
    from . import protocol

    unknown = [key for key in overrides if key not in Params.field_names()]
    if unknown:                # a mistyped keyword of simulate's own, too
        close = difflib.get_close_matches(unknown[0], Params.field_names() + KEYWORDS, n=1)
        raise ParameterError(f"simulate: unknown parameter {unknown[0]!r}"
                             + (f" (did you mean {close[0]!r}?)" if close else ""))
    # the parameters given, to warn about those that have no effect (Params.advise)
    if p is None:
        p = Params.from_dict(overrides, advise=False) if overrides else Params()
        given = overrides
    elif isinstance(p, Mapping):
        merged = {**p, **overrides}
        # as Params.replace: a threshold given as an override clears the other one
        for name, other in (("k_th", "f_th"), ("f_th", "k_th")):
            if overrides.get(name) is not None and other not in overrides:
                merged.pop(other, None)
        complete = set(p) >= set(Params.field_names())
        p = Params.from_dict(merged, advise=False)
        given = overrides if complete else merged      # a stored record: only the changes
    elif isinstance(p, Params):
        # a record built by Params(...) was never advised: its fields off their defaults
        given = overrides if getattr(p, "_advised", False) else {
            **{k: v for k, v in p.to_dict().items() if v != _DEFAULTS[k]}, **overrides}
        p = p._replaced(overrides) if overrides else p
    else:
        hint = " (a table row: tfm.Params.from_row(row))" if hasattr(p, "index") else ""
        raise ParameterError(f"simulate: expected a tfm.Params or a dict of parameters, got "
                             f"{type(p).__name__}{hint}")
    if given:
        p.advise({k: getattr(p, k) for k in given}, stacklevel=2)
    if progress is not None and not callable(progress):
        raise ParameterError(f"progress: expected a function of one step record, got {progress!r}")
    # arguments that would be silently ignored are refused
    if fields_path is not None and p.snapshots == "none":
        raise ParameterError("fields_path: applies only with snapshots = 'events' or K (this run stores none)")
    if fields_path is not None and Path(fields_path).suffix.lower() != ".nc":
        raise ParameterError(f"fields_path: {fields_path} must end with .nc (the snapshots are NetCDF4)")
    if fields_path is not None and not Path(fields_path).expanduser().resolve().parent.is_dir():
        raise ParameterError(f"fields_path: the folder of {fields_path} does not exist")
    if checkpoint is not None and not isinstance(checkpoint, (str, os.PathLike)):
        raise ParameterError(f"checkpoint: expected a file path (such as 'run.npz'), got {checkpoint!r}")
    for name, value in (("keep_checkpoint", keep_checkpoint), ("replace_checkpoint", replace_checkpoint)):
        if not isinstance(value, bool):
            raise ParameterError(f"{name}: expected True or False, got {value!r}")
    if checkpoint is None:
        for name, value, default in (("checkpoint_every", checkpoint_every, CHECKPOINT_EVERY),
                                     ("keep_checkpoint", keep_checkpoint, False),
                                     ("replace_checkpoint", replace_checkpoint, False)):
            if value != default:
                raise ParameterError(f"{name}: applies only with a checkpoint path (checkpoint=...)")
    ckpt = _checkpoint(p, checkpoint, checkpoint_every, replace_checkpoint) if checkpoint is not None else None
    if ckpt is not None:
        # a caller that removes the checkpoint itself, once the result is stored, gets the
        # finished curve saved too: a stop before the store then loses nothing
        ckpt.save_when_done = keep_checkpoint
    notes = check(p)                   # refuses a meaningless or oversized run up front
    for note in notes:
        warnings.warn(f"run {p.run_id}: {note}", RunWarning, stacklevel=2)
    prov = provenance()
    if ckpt is not None:
        ckpt.started_at = prov["started_at"]     # a saved state brings its own (protocol.run loads it)
    # an SI record is solved as its paper-units twin (tfm.units, L* = 1 m), then scaled back
    q = to_paper(p)
    # Ctrl-C while the compiled kernels load from Numba's cache was swallowed by a ctypes
    # callback, and the run went on: a signal waits for the end of the set-up (as for each
    # step, in tfm.protocol.run)
    setup = StopRequest(None, until="once the run is set up")
    with setup.installed():
        prob, layout = build_problem(q)
        if setup.pending:
            setup.deliver()
    writer = None
    if p.snapshots != "none":
        from .snapshots import SnapshotWriter, temporary_fields_path

        own_path = fields_path is None          # a temporary file: ours to remove on failure
        fields_path = fields_path or temporary_fields_path()
        writer = SnapshotWriter(fields_path, p, layout, prob)   # the run's record and units

    # the step records are the paper-units twin's: an SI run's caller gets newtons (its
    # lengths are metres already, L* = 1 m)
    newtons = force_scale(p) if p.units == "si" else None

    def observe(state, rec):
        if writer is not None:
            writer.observe(state, rec)
        if progress is not None:
            progress(rec if newtons is None else dataclasses.replace(rec, force=rec.force * newtons))

    try:
        out = protocol.run(q, prob, observe, ckpt)
        curve = curve_columns(out.steps)
        summary = summarize(curve, out, q, layout.n, layout.shape[0] if layout.shape else None)
        if p.units == "si":
            curve, summary = to_si_curve(curve, p), to_si_summary(summary, p)
        labels = unit_labels(p)
        summary["length_unit"], summary["force_unit"] = labels["length"], labels["force"]
        found = summary["warnings"]            # by the run; the notes were warned before it
        if writer is not None and writer.stopped:   # a flag: the snapshots asked for are not all there
            found = "; ".join(filter(None, [found, writer.stopped]))
        summary["warnings"] = "; ".join(filter(None, notes + [found]))
        if writer is not None:
            writer.close(summary)
    except BaseException:
        if writer is not None:
            writer.abort()
            if own_path:
                Path(fields_path).unlink(missing_ok=True)
        raise
    finally:
        if writer is not None:
            from .snapshots import LIVE_TEMPORARIES, UNCLAIMED
            LIVE_TEMPORARIES.discard(Path(fields_path))    # the result's from here on
            if own_path:
                UNCLAIMED.add(Path(fields_path))           # until write_curve moves it
    if found:             # the notes again made every pre-run note a warning twice
        warnings.warn(f"run {p.run_id}: {found}", RunWarning, stacklevel=2)
    # a resumed run says so: the steps before this one were computed by an earlier process
    prov["resumed_at_step"] = (ckpt.resumed_at or 0) if ckpt is not None else 0
    if ckpt is not None and ckpt.resumed_at:
        prov["started_at"] = ckpt.started_at     # when the run first started, not this process
    # always present (empty when none), so that every campaign table has the column
    prov["checkpoint_set_aside"] = (ckpt.set_aside or "") if ckpt is not None else ""
    # saves that failed (a full disk): the run had less protection than asked for
    prov["checkpoint_failed_saves"] = ckpt.failed_saves if ckpt is not None else 0
    prov["checkpoint_save_error"] = ckpt.save_error if ckpt is not None else ""
    if ckpt is not None and not keep_checkpoint:
        ckpt.remove()
    res = RunResult(p, curve, summary, prov)
    if writer is not None:
        res.fields_path = writer.path
        res._fields_stay = not own_path          # the caller's file: write_curve copies it
    return res


def _checkpoint(p: Params, path, every: float, replace: bool) -> Checkpoint:
    """The run's checkpoint, refused before any computation where it cannot serve, or
    where it would replace a file that is not this run's saved state (unless ``replace``)."""
    reason = why_not(p)
    if reason:
        raise ParameterError(f"checkpoint: {reason}")
    ckpt = Checkpoint(path, p.run_id, every)
    if ckpt.path.is_dir():
        raise ParameterError(f"checkpoint: {ckpt.path} is a folder; give a file path, such as "
                             f"{ckpt.path / 'run.npz'}")
    what = None if replace else ckpt.foreign()
    if what is not None:
        raise ParameterError(f"checkpoint: {ckpt.path} holds {what}; it is left alone: delete it, give "
                             "another path, or replace_checkpoint=True (tfm run: --overwrite) to replace it")
    try:
        ckpt.path.parent.mkdir(parents=True, exist_ok=True)
        # a folder that cannot take the file failed at the first save, ten minutes in
        probe = ckpt.path.with_name(f".{ckpt.path.name}.{os.getpid()}.probe.tmp")
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ParameterError(f"checkpoint: cannot write the folder {ckpt.path.parent}: "
                             f"{exc.strerror or exc}") from None
    return ckpt
