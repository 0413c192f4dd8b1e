"""Per-step curve table, run summary, provenance, and Parquet with metadata.

Columns of the curve follow the issue: step, phase, d, indent, force (compressive
positive, as in the paper's plots), contact_area, contact_radius, n_contact, n_snapped,
n_entered, rounds, solver_iters.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import math
import os
import platform
import shutil
import subprocess
from pathlib import Path
from typing import Any

from .config import SCHEMA_VERSION
from .params import Params

CURVE_COLUMNS = ["step", "phase", "d", "indent", "force", "contact_area", "contact_radius",
                 "n_contact", "n_snapped", "n_entered", "rounds", "solver_iters"]


def tfm_version() -> str:
    from . import __version__
    return __version__


def git_commit(here: Path | None = None) -> str | None:
    """The commit of the checkout that holds tfm (or ``here``), "-dirty" if it has changes."""
    here = Path(__file__).resolve().parent if here is None else here
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=5)
        if out.returncode != 0:
            return None
        # without the optional lock: `git status` otherwise refreshes the index under
        # .git/index.lock, and a run killed meanwhile (a campaign worker, say) left that lock
        # in the user's checkout, where every later git command then failed
        dirty = subprocess.run(["git", "--no-optional-locks", "status", "--porcelain", "--untracked-files=no"],
                               cwd=here, capture_output=True, text=True, timeout=5).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


_CODE_HASH = None
_COMMIT: list = []


def code_hash() -> str:
    """sha256 of tfm's source files (names and contents), read once per process, when a
    run first asks: the code this process computes with. A file edited later (during a
    long campaign, say) is not the code loaded, so it must not be read again."""
    global _CODE_HASH
    if _CODE_HASH is None:
        root = Path(__file__).resolve().parent
        h = hashlib.sha256()
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
        _CODE_HASH = h.hexdigest()
    return _CODE_HASH


def loaded_commit() -> str | None:
    """git_commit() of tfm's checkout, read once per process, with code_hash()."""
    if not _COMMIT:
        _COMMIT.append(git_commit())
    return _COMMIT[0]


def provenance() -> dict[str, Any]:
    import numba

    from .config import fft_workers
    import numpy as np
    import scipy
    return {
        "tfm_version": tfm_version(),
        "git_commit": loaded_commit(),
        "code_hash": code_hash(),
        "schema_version": SCHEMA_VERSION,
        "python_version": platform.python_version(),
        "numpy_version": np.__version__,
        "numba_version": numba.__version__,
        "scipy_version": scipy.__version__,
        "host": platform.node(),
        "started_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        # the threads it ran on (in a campaign, those of the worker that computed it)
        "numba_threads": numba.get_num_threads(),
        "fft_workers": fft_workers(),
    }


class RunResult:
    """What one run produced: its parameters, the curve, the summary and provenance.

    ``curve`` is a DataFrame. A run keeps it as NumPy columns (``curve_columns``) until it
    is first read, and writes its table from them: `tfm run` then never imports pandas,
    which took 0.1 s of its 1.4 s at 1/128 (2026-11-24)."""

    def __init__(self, params: Params, curve, summary: dict[str, Any], provenance: dict[str, Any] | None = None,
                 fields_path: Path | None = None):
        self.params = params
        self._curve = curve                 # a DataFrame, or a dict of columns
        self.summary = summary
        self.provenance = {} if provenance is None else provenance
        self.fields_path = fields_path      # the field snapshots (NetCDF4), if any
        # the file at fields_path stays where it is (beside an earlier table, or where the
        # caller of simulate asked for it): write_curve copies it instead of moving it
        self._fields_stay = False

    @property
    def curve(self) -> pd.DataFrame:
        if isinstance(self._curve, dict):
            self._curve = curve_frame(self._curve)
        return self._curve

    @curve.setter
    def curve(self, value) -> None:
        self._curve = value

    def columns(self) -> dict[str, Any]:
        """The curve as NumPy columns (CURVE_COLUMNS), without making a DataFrame."""
        if isinstance(self._curve, dict):
            return dict(self._curve)
        return {c: self._curve[c].to_numpy(dtype=object if c == "phase" else None) for c in CURVE_COLUMNS}

    def __setstate__(self, state: dict) -> None:
        if "curve" in state:                # pickled when RunResult was a dataclass
            state["_curve"] = state.pop("curve")
        state.setdefault("_fields_stay", state.pop("_fields_placed", False))
        self.__dict__.update(state)

    def __repr__(self) -> str:
        return (f"RunResult(run_id={self.params.run_id!r}, steps={self.summary.get('n_steps')}, "
                f"pull_off_force={self.summary.get('pull_off_force')!r})")

    @property
    def ok(self) -> bool:
        return not self.summary["warnings"]

    def write_curve(self, path: str | os.PathLike) -> Path:
        """Write the curve table (``.parquet``); field snapshots, if any, move beside it as
        ``<stem>.fields.nc`` (copied, if an earlier write_curve placed them beside another
        table or simulate wrote them to a path of the caller's) and the table's metadata
        names them (``fields``)."""
        from .units import unit_labels

        path = Path(path)
        if path.suffix.lower() != ".parquet":
            raise ValueError(f"write_curve: {path} must end with .parquet (the table is Parquet)")
        extra = {"units": unit_labels(self.params)}
        if self.fields_path is not None:
            dest = fields_path_for(path)
            if Path(self.fields_path).resolve() != dest.resolve():
                # through a temporary name in the destination folder: a kill leaves no half file
                dest.parent.mkdir(parents=True, exist_ok=True)
                with through_temporary(dest) as tmp:
                    if self._fields_stay:
                        shutil.copyfile(self.fields_path, tmp)
                    else:
                        from .snapshots import UNCLAIMED
                        shutil.move(str(self.fields_path), tmp)
                        UNCLAIMED.discard(Path(self.fields_path))
                self.fields_path = dest
            self._fields_stay = True         # the table keeps its own
            extra["fields"] = dest.name
        written = write_table(self._curve, path, self.params, self.provenance, self.summary, extra=extra)
        if self.fields_path is None:
            # snapshots left beside the path by the table just replaced are not this run's
            # (views would have drawn them with this curve)
            fields_path_for(path).unlink(missing_ok=True)
        return written


def fields_path_for(curve_path: str | os.PathLike) -> Path:
    """Where a curve table's field snapshots live: beside it, ``<stem>.fields.nc``."""
    curve_path = Path(curve_path)
    return curve_path.with_name(curve_path.stem + ".fields.nc")


def _gone(pid: int) -> bool:
    """Whether no process ``pid`` runs on this machine (one that is not ours counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:
        return False
    return False


def remove_dead_files(folder: Path, globs: list[str], pattern, min_age: float = 0.0,
                      own: bool = False) -> list[Path]:
    """Remove the files of ``folder`` matching one of ``globs`` whose name fully matches
    ``pattern`` (a compiled regex whose first group that matched is the writer's pid), whose
    pid no longer runs here, untouched for ``min_age`` seconds and, with ``own``, ours."""
    import time

    removed = []
    try:
        candidates = [path for glob in globs for path in folder.glob(glob)]
    except OSError:
        return removed
    for path in candidates:
        match = pattern.fullmatch(path.name)
        if not match:
            continue
        try:
            st = path.stat()
            if ((not own or st.st_uid == os.getuid()) and time.time() - st.st_mtime >= min_age
                    and _gone(int(next(g for g in match.groups() if g is not None)))):
                path.unlink()
                removed.append(path)
        except OSError:
            pass
    return removed


@contextlib.contextmanager
def through_temporary(path: str | os.PathLike, keep_suffix: bool = False):
    """Yield a temporary name beside ``path`` to write to, then move it into place: a killed
    or failed write leaves an earlier file whole, and no stray temporary file. The name is
    ``.<name>.<pid>.tmp``, or ``.<stem>.<pid>.tmp<suffix>`` for writers that take the
    format from the suffix (figures); ``remove_dead_temporaries`` knows both."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}" if keep_suffix
                         else f".{path.name}.{os.getpid()}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def remove_dead_temporaries(*outputs: str | os.PathLike) -> list[Path]:
    """Remove what a killed tfm process (kill -9, a crash) left beside the outputs: the
    temporary files it wrote them through, named after the output and its pid
    (``.<name>.<pid>.tmp``, ``.<stem>.<pid>.tmp<suffix>``, ``.<stem>.<pid>.worker<suffix>``),
    whose pid no longer runs here. Other files are never touched."""
    import re

    removed = []
    for out in map(Path, outputs):
        stem, suffix = re.escape(out.stem), re.escape(out.suffix)
        pattern = re.compile(rf"\.(?:{re.escape(out.name)}\.(\d+)\.(?:probe\.)?tmp"
                             rf"|{stem}\.(\d+)\.(?:tmp|worker){suffix})")
        removed += remove_dead_files(out.parent, [f".{out.stem}.*"], pattern)
    return removed


#: integer columns of the curve; the others are floats, and "phase" ("load", "unload")
INT_COLUMNS = ("step", "n_contact", "n_snapped", "n_entered", "rounds", "solver_iters")


def curve_columns(steps) -> dict[str, Any]:
    """The curve of ``steps`` (tfm.solver.StepRecord) as NumPy columns, CURVE_COLUMNS in order."""
    import numpy as np

    def column(name, dtype):
        return np.array([getattr(s, name) for s in steps], dtype=dtype)

    cols = {name: column(name, np.int64) for name in INT_COLUMNS}
    cols["phase"] = column("phase", object)
    for name in ("d", "force", "contact_area"):
        cols[name] = column(name, np.float64)
    cols["indent"] = -cols["d"]
    cols["contact_radius"] = np.sqrt(cols["contact_area"] / math.pi)
    return {c: cols[c] for c in CURVE_COLUMNS}


def curve_frame(columns) -> pd.DataFrame:
    """The DataFrame of ``curve_columns``."""
    import pandas as pd

    return pd.DataFrame({c: (list(v) if c == "phase" else v) for c, v in columns.items()})


def summarize(curve, out, p: Params, n_springs: int, grid_side: int | None) -> dict[str, Any]:
    import numpy as np

    col = {c: np.asarray(curve[c]) for c in CURVE_COLUMNS}
    n = col["step"].size
    unload = col["phase"] == "unload"
    tension = -col["force"]
    k = int(np.argmax(tension)) if n else 0
    # no tension at any step (no adhesion): no pull-off, so no indent or radius for it (the
    # argmax picked some step at P = 0: -0.0 and a radius of 0.018 at 1/32)
    pulled = n > 0 and tension[k] > 0.0
    warnings = []
    if out.edge_steps:
        if p.shape == "height_map":
            # extent_margin does not apply, and the map bounds the extent
            grow = ("enlarge extent, if the map covers it, or use a larger map or a shallower max_indent"
                    if p.extent is not None else "use a larger map or a shallower max_indent (the grid is "
                    "the largest square that the map covers)")
        else:
            grow = "enlarge extent" if p.extent is not None else "raise extent_margin or give a larger extent"
        warnings.append(f"contact reached the grid edge at {out.edge_steps} steps "
                        f"(half-width {p.half_width:g}); {grow}")
    if out.solver_failures:
        warnings.append(f"contact solve did not converge {out.solver_failures} times "
                        f"(worst relative residual {out.max_residual:.2e}, tol {p.tol:g}); raise max_iter"
                        + (", or reduce jitter or raise self_term: a cluster of close springs can make the "
                           "compliance indefinite" if p.layout == "jittered" else
                           ", or raise self_term: the compliance may be nearly indefinite"
                           if p.layout == "hexagonal" else ""))
    if out.rounds_exceeded:
        warnings.append(f"snap/enter rounds hit max_rounds={p.max_rounds} at {out.rounds_exceeded} steps")
    if getattr(out, "loads_short", 0):
        warnings.append(f"force control: {out.loads_short} load steps stopped below their target load: the flat "
                        "moved twice the Hertz depth of the peak load without reaching it (a contact softer than "
                        "Hertz's?); the curve's largest load is max_force")
    if not out.unload_complete:
        from .protocol import default_max_unload_steps
        cap = p.max_unload_steps or default_max_unload_steps(p)
        warnings.append(f"unloading stopped at max_unload_steps with springs still in contact (after {cap:,} "
                        "unloading steps): raise max_unload_steps"
                        + (", or load_step" if p.control == "force" else ", or step"))
    from .guards import contact_reached_note
    few = contact_reached_note(p, int(col["n_contact"].max()) if n else 0)
    if few:
        warnings.append(few)
    first_snap = np.flatnonzero(unload & (col["n_snapped"] > 0))
    # force control: the last load the contact held before it broke (tfm.protocol)
    held = np.flatnonzero(unload & (col["n_contact"] > 0))
    jump = p.control == "force" and out.unload_complete and held.size > 0
    j = held[-1] if jump else 0
    # a contact that closes without tension (no adhesion) has no jump-off, as no pull-off
    jump = jump and -col["force"][j] > 0.0
    return {
        "jump_off_force": float(-col["force"][j]) if jump else math.nan,
        "jump_off_contact_radius": float(col["contact_radius"][j]) if jump else math.nan,
        "jump_off_indent": float(col["indent"][j]) if jump else math.nan,
        "pull_off_force": float(tension[k]) if pulled else 0.0,
        "pull_off_indent": float(col["indent"][k]) if pulled else math.nan,
        "pull_off_contact_radius": float(col["contact_radius"][k]) if pulled else math.nan,
        # force control: the depth the peak load reached (delta_max only sized the grid)
        "max_indent": (float(col["indent"].max()) if n else 0.0) if p.control == "force"
        else p.delta_max,
        "f_th": p.threshold_force,
        "max_force": float(col["force"].max()) if n else 0.0,
        "max_contact_radius": float(col["contact_radius"].max()) if n else 0.0,
        "first_snap_indent": float(col["indent"][first_snap[0]]) if first_snap.size else math.nan,
        "n_steps": int(n),
        "n_solves": int(out.n_solves),
        "solver_iters": int(out.solver_iters),
        "max_residual": float(out.max_residual),
        "n_springs": int(n_springs),
        "grid_side": grid_side,
        "half_width": p.half_width,
        "wall_time": float(out.wall_time),
        # steps with a solve taken on all Numba threads (the thread choice varies with the
        # machine's load: like wall_time, not part of the run's result; docs/tables.md)
        "threaded_steps": int(out.threaded_steps),
        "contact_reached_edge": bool(out.edge_steps),
        "solver_not_converged": bool(out.solver_failures),
        "rounds_exceeded": bool(out.rounds_exceeded),
        "unload_complete": bool(out.unload_complete),
        "warnings": "; ".join(warnings),
    }


def _json_default(obj):
    import numbers
    if isinstance(obj, numbers.Integral):      # NumPy integers
        return int(obj)
    if isinstance(obj, numbers.Real):
        return float(obj)
    return str(obj)


def arrow_column(values):
    """A NumPy column as an Arrow array of the type pandas would have written. Numbers and
    strings (as objects) are made from their buffers: ``pyarrow.array`` imports pandas to
    probe its argument, and pandas is what writing a table without it saves. Any other
    column (booleans, say, which Arrow packs as bits) goes through ``pyarrow.array``."""
    import numpy as np
    import pyarrow as pa

    values = np.asarray(values)
    if values.dtype.kind == "U" or (values.dtype == object and all(isinstance(v, str) for v in values)):
        data = [v.encode() for v in values.tolist()]
        offsets = np.zeros(len(data) + 1, dtype=np.int64)
        np.cumsum([len(b) for b in data], out=offsets[1:])
        return pa.Array.from_buffers(pa.large_string(), len(data),
                                     [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))])
    if values.dtype.kind in "iuf" and values.ndim == 1:
        values = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("="))
        return pa.Array.from_buffers(pa.from_numpy_dtype(values.dtype), values.size, [None, pa.py_buffer(values)])
    return pa.array(values, type=pa.large_string() if values.dtype == object else None)


def write_table(df, path, params: Params | None = None, prov=None, summary=None,
                extra: dict[str, Any] | None = None) -> Path:
    """Write a table (a DataFrame, or a dict of NumPy columns) atomically (temporary file,
    then rename) with tfm metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(df, dict):
        table = pa.table({c: arrow_column(v) for c, v in df.items()})
    else:
        table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[b"tfm.schema_version"] = str(SCHEMA_VERSION).encode()
    meta[b"tfm.version"] = tfm_version().encode()
    if params is not None:
        meta[b"tfm.params"] = params.canonical_json().encode()
        meta[b"tfm.run_id"] = params.run_id.encode()
    if prov is not None:
        meta[b"tfm.provenance"] = json.dumps(prov, sort_keys=True, default=_json_default).encode()
    if summary is not None:
        meta[b"tfm.summary"] = json.dumps(summary, sort_keys=True, default=_json_default).encode()
    for key, value in (extra or {}).items():
        meta[f"tfm.{key}".encode()] = json.dumps(value, sort_keys=True, default=_json_default).encode()
    # the same record as pandas' DataFrame.attrs["tfm"]: pd.read_parquet shows it, and a
    # frame written back with to_parquet keeps it (pandas drops the tfm.* keys)
    meta[PANDAS_ATTRS] = json.dumps({"tfm": _decode(meta)}, sort_keys=True).encode()
    table = table.replace_schema_metadata(meta)
    with through_temporary(path) as tmp:
        # page checksums: a flipped bit on disk is found when the file is read
        # (read_checked), where it was read as another number
        pq.write_table(table, tmp, write_page_checksum=True)
    return path


def read_checked(path):
    """A Parquet table as a DataFrame, its page checksums verified (files that have them)."""
    import pyarrow.parquet as pq

    return pq.read_table(path, page_checksum_verification=True).to_pandas()


def read_metadata(path) -> dict[str, Any]:
    """The tfm metadata of a Parquet file, decoded (params, provenance, summary, ...)."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    out = _decode(meta)
    if not out and PANDAS_ATTRS in meta:
        # written back by pandas: the record survives in DataFrame.attrs
        try:
            out = json.loads(meta[PANDAS_ATTRS]).get("tfm", {})
        except (json.JSONDecodeError, AttributeError):
            out = {}
    return out


PANDAS_ATTRS = b"PANDAS_ATTRS"      # where pandas (>= 2.1) keeps DataFrame.attrs in Parquet


def _decode(meta: dict) -> dict[str, Any]:
    """The tfm.* entries of Parquet metadata, JSON-decoded where they are JSON."""
    out = {}
    for key, value in meta.items():
        k = key.decode()
        if k.startswith("tfm."):
            v = value.decode()
            try:
                out[k[4:]] = json.loads(v)
            except json.JSONDecodeError:
                out[k[4:]] = v
    return out
