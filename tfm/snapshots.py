"""Field snapshots of a run: per spring F, u and contact state at chosen steps, streamed
to a compressed NetCDF4 file (``<curve stem>.fields.nc``) while the run goes on.

Format: NetCDF4 (HDF5) written with h5netcdf. One self-describing file per run, so it
can be renamed into place atomically and stored beside its curve table; CF-style names,
units and flag meanings; read in one line by xarray (``xr.open_dataset(path)``), and by
netCDF tools in any language. ContactMechanics stores its fields the same way. (Zarr
would be a directory of many small files per run, and is not installed here.)

Layout::

    dimensions  step (unlimited: one entry per snapshot, in the order written),
                x, y on the square grid (F[step, x, y]), else spring (F[step, spring])
    per spring  x, y (coordinates), x0 (undeformed height, NaN off the body), f_th, area
    per step    step (the curve table's step), d, force (compression > 0), n_contact,
                phase, event ("" or labels such as "every_10", "pull_off,first_snap")
    fields      F (spring force, tension > 0), u (displacement), state
                (0 never in contact, 1 in contact, 2 released: was in contact, is not)
    attributes  run_id, params (JSON), summary (JSON), <event>_step for each event,
                force_unit, length_unit, force_scale

An SI run's file is in newtons and metres, like its table, and holds the run's own SI
record and run id; the run is solved as its paper-units twin (tfm.units), so forces are
written times force_scale (newtons per F*; lengths keep their numbers, L* = 1 m).

``snapshots = "events"`` stores the maximum load (largest compressive force), the
pull-off (largest tensile force), the first snap and the last step in contact;
``snapshots = k`` also stores every k-th step (step % k == 0). Memory and disk stay
bounded: a snapshot is written when its step is done; events known only later (the
force maxima, the last step in contact) keep one O(N) candidate copy each, written when
the run ends. A step stored twice is stored once, with both labels. The step dimension is
in writing order: ``ds.sortby("step")`` orders it, ``ds.sel(step=k)`` picks a step.
"""
from __future__ import annotations

import atexit
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .results import _json_default, tfm_version
from .units import force_scale

STATE_NEVER, STATE_CONTACT, STATE_RELEASED = 0, 1, 2
EVENTS = ("max_load", "pull_off", "first_snap", "last_contact")
# CF unit strings of (length, force, area) per unit system
CF_UNITS = {"paper": ("L*", "F*", "L*^2"), "si": ("m", "N", "m^2")}
# free disk kept beside the snapshots, for the table, the figure and HDF5's own metadata
DISK_RESERVE = 64 * 2**20


# Temporary files this process is writing now (a run's snapshots in the temporary folder
# and the hidden .tmp a writer streams to): a campaign's pool worker stopped by SIGTERM
# removes them before it dies (tfm.campaign.runner); they stayed in /tmp for an hour.
LIVE_TEMPORARIES: set[Path] = set()


# Finished runs' snapshots in the temporary folder that no RunResult.write_curve has
# moved beside a table yet: removed when the process exits (they stayed in /tmp for an
# hour, until a later run's clean-up, for every simulate() whose result was not written).
UNCLAIMED: set[Path] = set()


@atexit.register
def _remove_unclaimed() -> None:
    for path in list(UNCLAIMED):
        Path(path).unlink(missing_ok=True)
    UNCLAIMED.clear()


def remove_live_temporaries() -> None:
    for path in list(LIVE_TEMPORARIES):
        try:
            path.unlink()
        except OSError:
            pass
        LIVE_TEMPORARIES.discard(path)


def temporary_fields_path() -> Path:
    """A new file in the temporary folder for a run's snapshots (moved beside its table
    when that is written), named with this process's pid so that the files of a killed
    process can be told from a running one's (remove_dead_temporary_fields). Listed in
    LIVE_TEMPORARIES until its run ends (tfm.simulate)."""
    remove_dead_temporary_fields()
    fd, name = tempfile.mkstemp(prefix=f"tfm-{os.getpid()}-", suffix=".fields.nc")
    os.close(fd)
    LIVE_TEMPORARIES.add(Path(name))
    return Path(name)


def remove_dead_temporary_fields(folder: str | os.PathLike | None = None,
                                 min_age: float = 3600.0) -> list[Path]:
    """Remove the temporary snapshot files (and their ``.tmp`` being written) that a killed
    process left in the temporary folder: ours, from a pid that no longer runs here, and
    untouched for ``min_age`` seconds (a process of another pid namespace sharing the
    folder would be writing to its file)."""
    import re

    from .results import remove_dead_files

    pattern = re.compile(r"\.?tfm-(\d+)-[^/]*\.fields\.nc(?:\.\d+\.tmp)?")
    return remove_dead_files(Path(folder or tempfile.gettempdir()),
                             ["tfm-*.fields.nc", ".tfm-*.fields.nc.*.tmp"], pattern, min_age, own=True)


# Bytes a snapshot takes per spring on disk: F and u in float64 and the state byte are 17
# before compression; compressed, 5.8-6.4 measured (smooth paraboloid, 1/32 and 1/64,
# snapshots 1, 2026-11-25). Rough surfaces compress less.
BYTES_PER_SPRING_RAW, BYTES_PER_SPRING_PACKED = 17.0, 6.0
LARGE_SNAPSHOTS = 2**30        # estimates above this are said before the run


def every(k: int, what: str = "step") -> str:
    """'every step', 'every 2nd step', 'every 23rd step', 'every 11th step'."""
    if k == 1:
        return f"every {what}"
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"every {k}{suffix} {what}"


def size_note(p, folder: str | os.PathLike | None = None) -> str | None:
    """What to say before a run with ``snapshots = k`` (None: nothing): the files' size
    when it may be large, or exceed the free disk of the temporary folder they are written
    to first (the disk guard stops them when it fills, keeping the curve); and a k so large
    that few steps besides step 0 and the events are stored. The unloading has at least
    as many steps as the loading, usually more (about 1.6 times at spacing 1/64)."""
    from .guards import n_springs
    from .protocol import n_loading_steps

    if not isinstance(p.snapshots, int):
        return None
    k, loading = p.snapshots, n_loading_steps(p)
    if k > 2 * loading:
        return (f"snapshots: {every(k)}, but the loading has {loading} steps (the unloading usually "
                "1-2 times as many): few steps besides step 0 and the events (snapshots='events') will be stored")
    count = 2 * loading // k + 1          # at least: the unloading as long as the loading
    n = n_springs(p)
    low, high = count * n * BYTES_PER_SPRING_PACKED, count * n * BYTES_PER_SPRING_RAW
    try:
        free = shutil.disk_usage(folder or tempfile.gettempdir()).free
    except OSError:
        free = None
    if high < LARGE_SNAPSHOTS and (free is None or high < free / 2):
        return None
    room = "" if free is None else f"; {free / 2**30:.1f} GiB free in {folder or tempfile.gettempdir()}, where they are written first"
    return (f"snapshots: {every(k)} of {n:,} springs: at least {count:,} snapshots "
            f"(the unloading as long as the loading), {low / 2**30:.2g}-{high / 2**30:.2g} GiB "
            f"(compressed, and not){room}. A larger k, or snapshots='events', keeps the files small; "
            "the snapshots stop, keeping the curve, if the disk fills")


class _Copy:
    """One step's fields, copied (an event candidate)."""

    __slots__ = ("rec", "F", "u", "state")

    def __init__(self, rec, F, u, state):
        self.rec = _plain(rec)
        self.F, self.u, self.state = F.copy(), u.copy(), state.copy()


def _plain(rec) -> dict:
    return {"step": int(rec.step), "phase": rec.phase, "d": float(rec.d), "force": float(rec.force),
            "n_contact": int(rec.n_contact), "n_snapped": int(rec.n_snapped)}


class SnapshotWriter:
    """Streams snapshots of one run to ``path`` (through a temporary file renamed at close).
    ``p`` is the run's own record; ``layout`` and ``prob`` (and the states observed) are
    those of the solve, in paper units."""

    def __init__(self, path, p, layout, prob):
        import h5netcdf
        import h5py

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        LIVE_TEMPORARIES.add(self._tmp)
        self.every = p.snapshots if isinstance(p.snapshots, int) else None
        self.grid = layout.shape
        self._index: dict[int, int] = {}        # step -> position along the step dimension
        self._labels: list[str] = []
        self._ever = np.zeros(layout.n, dtype=bool)
        self._state = np.zeros(layout.n, dtype=np.int8)
        self._best_load = self._best_pull = self._prev = None
        self._first_snap_done = False
        self._events: dict[str, int] = {}
        self._snapshot_bytes = 17 * layout.n    # F and u (f8) and state (i1), before compression
        self.stopped: str | None = None         # why snapshots stopped early (_room)
        self._stopped_step: int | None = None
        self.scale = force_scale(p)           # newtons per F* (1 in paper units)
        L, F_, A = CF_UNITS[p.units]
        units = ("the paper's nondimensional units: length L*, force F* = 2 pi G L*^2 / (1 - nu)"
                 if p.units == "paper" else
                 f"SI: lengths in m, forces in N (solved in the paper's units, L* = 1 m, F* = {self.scale!r} N)")
        f = self._f = h5netcdf.File(self._tmp, "w")
        f.attrs.update({
            "title": "tfm field snapshots (threshold-force model of adhesion)",
            "Conventions": "CF-1.8",
            "source": f"tfm {tfm_version()}",
            "run_id": p.run_id,
            "params": p.canonical_json(),
            "units": units,
            "length_unit": L,
            "force_unit": F_,
            "force_scale": self.scale,
            "sign_convention": "F > 0 is tension; force = -sum(F) is compressive-positive; indent = -d",
            "snapshots": str(p.snapshots),
        })
        if self.grid is not None:
            n, m = self.grid
            f.dimensions = {"step": None, "x": n, "y": m}
            space = ("x", "y")
            xs = layout.x.reshape(self.grid)[:, 0]
            ys = layout.y.reshape(self.grid)[0, :]
            self._var("x", ("x",), xs, "spring x coordinate", L)
            self._var("y", ("y",), ys, "spring y coordinate", L)
        else:
            f.dimensions = {"step": None, "spring": layout.n}
            space = ("spring",)
            self._var("x", space, layout.x, "spring x coordinate", L)
            self._var("y", space, layout.y, "spring y coordinate", L)
        self._space = space
        x0 = np.where(np.isfinite(prob.x0), prob.x0, np.nan)
        self._var("x0", space, self._shape(x0), "undeformed surface height (apex at 0; NaN: no surface)", L)
        self._var("f_th", space, self._shape(prob.f_th * self.scale), "tensile threshold force of the spring", F_)
        self._var("area", space, self._shape(prob.area), "tributary area of the spring", A)
        self._var("step", ("step",), None, "step of the curve table", "1", dtype="i8")
        self._var("d", ("step",), None, "height of the rigid flat (indentation = -d)", L, dtype="f8")
        self._var("force", ("step",), None, "total force, compression > 0 (= -sum F)", F_, dtype="f8")
        self._var("n_contact", ("step",), None, "springs in contact", "1", dtype="i8")
        text = h5py.string_dtype()
        f.create_variable("phase", ("step",), dtype=text, chunks=(256,))
        f.create_variable("event", ("step",), dtype=text, chunks=(256,))
        f.variables["event"].attrs["long_name"] = "events at this step, comma-separated: " + ", ".join(EVENTS) \
            + ", every_<k>"
        chunks = (1,) + tuple(f.dimensions[s].size for s in space)
        comp = dict(compression="gzip", compression_opts=4, shuffle=True, chunks=chunks)
        self._var("F", ("step",) + space, None, "spring force (tension > 0)", F_, dtype="f8", **comp)
        self._var("u", ("step",) + space, None, "spring displacement u = C F (= d - x0 in contact, to the solver tolerance; to the tree's error with operator tree)", L,
                  dtype="f8", **comp)
        v = self._var("state", ("step",) + space, None, "contact state", "1", dtype="i1", **comp)
        v.attrs["flag_values"] = np.array([STATE_NEVER, STATE_CONTACT, STATE_RELEASED], dtype=np.int8)
        v.attrs["flag_meanings"] = "never_in_contact in_contact released"
        if self.grid is None:
            # CF auxiliary coordinates: xarray then gives each spring field its x and y
            # (they were plain data variables beside a 'spring' axis with no coordinate)
            for name in ("x0", "f_th", "area", "F", "u", "state"):
                f.variables[name].attrs["coordinates"] = "x y"

    # ---- writing -----------------------------------------------------------
    def _shape(self, a):
        return a.reshape(self.grid) if self.grid is not None else a

    def _var(self, name, dims, data, long_name, units, dtype=None, **kw):
        if data is None and "chunks" not in kw:
            kw["chunks"] = (256,)           # a growing 1-D variable (no heuristic on size 0)
        v = self._f.create_variable(name, dims, dtype=dtype if data is None else None, data=data, **kw)
        v.attrs["long_name"] = long_name
        v.attrs["units"] = units
        return v

    def observe(self, state, rec) -> None:
        """Called after every recorded step, with the state that produced ``rec``."""
        contact = state.contact
        self._ever |= contact
        st = self._state
        st[:] = STATE_NEVER
        st[self._ever] = STATE_RELEASED
        st[contact] = STATE_CONTACT
        if self._prev is not None and rec.n_contact == 0 and self._prev.rec["n_contact"] > 0:
            self._settle("last_contact", self._prev)
        if self.every is not None and rec.step % self.every == 0:
            self._write(_plain(rec), state.F, state.u, st, f"every_{self.every}")
        # the summary's first snap (first_snap_indent): an unloading one; with F_th = 0 springs
        # also snap while loading
        if rec.n_snapped > 0 and rec.phase == "unload" and not self._first_snap_done:
            self._first_snap_done = True
            self._write(_plain(rec), state.F, state.u, st, "first_snap")
        if self._best_load is None or rec.force > self._best_load.rec["force"]:
            self._best_load = _Copy(rec, state.F, state.u, st)
        # the pull-off is the largest tension (force < 0), as in the summary: a run that
        # never pulls has none
        if rec.n_contact > 0 and rec.force < 0 and (self._best_pull is None
                                                    or rec.force < self._best_pull.rec["force"]):
            self._best_pull = _Copy(rec, state.F, state.u, st)
        self._prev = _Copy(rec, state.F, state.u, st)

    def _settle(self, event, snap: _Copy) -> None:
        self._write(snap.rec, snap.F, snap.u, snap.state, event)

    def _room(self, step: int) -> bool:
        """Whether the disk has room for another snapshot and the table after it. HDF5 on a
        full disk raised thousands of errors in its destructors and then crashed the
        process (segfault), taking the curve with it; so the snapshots stop first, while
        the file can still be closed (``stopped``, a flag of the run)."""
        if self.stopped is None:
            free = shutil.disk_usage(self._tmp.parent).free
            need = 2 * self._snapshot_bytes + DISK_RESERVE
            if free < need:
                # enough decimals that the two differ (both read 64.6 MiB in a hunt)
                digits = next((d for d in range(1, 7) if f"{free / 2**20:.{d}f}" != f"{need / 2**20:.{d}f}"), 6)
                self._stopped_step = step
                self.stopped = (f"field snapshots stopped at step {step}: {free / 2**20:.{digits}f} MiB free on "
                                f"{self._tmp.parent}, under the {need / 2**20:.{digits}f} MiB kept for the next "
                                "snapshot and the table; the file holds the steps before")
        return self.stopped is None

    def _write(self, rec: dict, F, u, state, label: str) -> None:
        step = rec["step"]
        # a step already in the file only gains a label: that, and its event, also once
        # the snapshots have stopped (the file's max_load step lost its name)
        if step not in self._index and not self._room(step):
            return
        if label.split("_")[0] != "every":
            self._events[label] = step
        if step in self._index:
            i = self._index[step]
            self._labels[i] = f"{self._labels[i]},{label}" if self._labels[i] else label
            self._f.variables["event"][i] = self._labels[i]
            return
        f = self._f
        i = len(self._labels)
        f.resize_dimension("step", i + 1)
        v = f.variables
        v["step"][i] = step
        v["d"][i] = rec["d"]
        v["force"][i] = rec["force"] * self.scale
        v["n_contact"][i] = rec["n_contact"]
        v["phase"][i] = rec["phase"]
        v["event"][i] = label
        v["F"][i] = self._shape(F * self.scale if self.scale != 1.0 else F)
        v["u"][i] = self._shape(u)
        v["state"][i] = self._shape(state)
        self._index[step] = i
        self._labels.append(label)

    def close(self, summary: dict | None = None) -> Path:
        """Write the settled events, the summary, and move the file into place."""
        if self._best_load is not None:
            self._settle("max_load", self._best_load)
        if self._best_pull is not None:
            self._settle("pull_off", self._best_pull)
        # last_contact is settled when contact is lost (observe): a run that ends with
        # springs in contact (unloading capped) has none
        for event, step in self._events.items():
            self._f.attrs[f"{event}_step"] = step
        if summary is not None:
            self._f.attrs["summary"] = json.dumps(summary, sort_keys=True, default=_json_default)
        if self.stopped is not None:     # the views say why later steps have no snapshot
            self._f.attrs["stopped_at_step"] = self._stopped_step
        self._f.close()
        os.replace(self._tmp, self.path)
        LIVE_TEMPORARIES.discard(self._tmp)
        return self.path

    def abort(self) -> None:
        try:
            self._f.close()
        finally:
            self._tmp.unlink(missing_ok=True)
            LIVE_TEMPORARIES.discard(self._tmp)


# ---- reading (no xarray needed; xarray users: xr.open_dataset(path)) -------------
def readable(path) -> bool:
    """Whether ``path`` is a snapshots file that opens with its steps and fields (a
    truncated file fails to open)."""
    try:
        import h5py

        with h5py.File(path, "r") as f:
            return "step" in f and "F" in f
    except (OSError, ValueError):
        return False


class Fields:
    """A fields file opened for reading: ``steps`` (sorted), ``snapshot(step)``."""

    def __init__(self, path):
        import h5netcdf

        self.path = Path(path)
        with h5netcdf.File(self.path, "r") as f:
            v = f.variables
            self.attrs = dict(f.attrs)
            self.grid = "spring" not in f.dimensions
            self.x = v["x"][...]
            self.y = v["y"][...]
            self.x0 = v["x0"][...]
            self.f_th = v["f_th"][...]
            self._steps = np.asarray(v["step"][...], dtype=np.int64)
            self.d = np.asarray(v["d"][...])
            self.force = np.asarray(v["force"][...])
            self.n_contact = np.asarray(v["n_contact"][...])
            self.events = [e.decode() if isinstance(e, bytes) else str(e) for e in v["event"][...]]
        self.params = json.loads(self.attrs["params"])
        self.steps = np.sort(self._steps)
        self._h5 = None
        # the forces on file are F* times this (files written before it was recorded: F*)
        self.file_scale = float(self.attrs.get("force_scale", 1.0))
        self.force_scale = self.file_scale

    def use_force_scale(self, scale: float) -> None:
        """Give forces (F, f_th, force) in the units of a run whose force unit is
        ``scale`` F* (tfm.units.force_scale of its record: newtons for an SI run; lengths
        keep their numbers, L* = 1 m), whatever the file holds."""
        ratio = float(scale) / self.force_scale
        self.f_th = self.f_th * ratio
        self.force = self.force * ratio
        self.force_scale = float(scale)

    def event_step(self, event: str) -> int | None:
        value = self.attrs.get(f"{event}_step")
        return None if value is None else int(value)

    def position(self, step: int) -> int:
        hits = np.flatnonzero(self._steps == step)
        if not hits.size:
            raise KeyError(f"{self.path}: no snapshot at step {step}; stored steps: "
                           f"{', '.join(map(str, self.steps[:20]))}{' ...' if self.steps.size > 20 else ''}")
        return int(hits[0])

    def snapshot(self, step: int) -> dict:
        """Arrays F, u, state (grid-shaped on the square grid) and d, force, n_contact, event."""
        i = self.position(step)
        if self._h5 is None:
            import h5py                     # plain h5py reads a slice ~50x faster than h5netcdf

            self._h5 = h5py.File(self.path, "r")
        try:
            out = {name: self._h5[name][i] for name in ("F", "u", "state")}
        except OSError as exc:           # a chunk damaged on disk (the header read fine)
            raise OSError(f"{self.path}: the snapshot of step {step} cannot be read ({exc}); the file is "
                          "damaged: rerun the run with --snapshots to store it again") from None
        if self.force_scale != self.file_scale:
            out["F"] = out["F"] * (self.force_scale / self.file_scale)
        out.update(step=int(step), d=float(self.d[i]), force=float(self.force[i]),
                   n_contact=int(self.n_contact[i]), event=self.events[i])
        return out

    def close(self) -> None:
        if self._h5 is not None:
            self._h5.close()
            self._h5 = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
