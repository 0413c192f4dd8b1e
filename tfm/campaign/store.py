"""Where a campaign's results live, and how they are written so that a kill never corrupts them.

Layout under ``<results_dir>/<campaign name>/``::

    runs/<run_id>.parquet      one finished run: its curve, with params, summary and
                               provenance in the Parquet metadata (tfm.results.write_table)
    runs/<run_id>.fields.nc    its field snapshots (NetCDF4, tfm.snapshots), if the run
                               asked for them; summary column ``fields_path`` points to it
    failures/<run_id>.json     one failed run: parameters, error and traceback
    checkpoints/<run_id>.npz   the saved state of a run in progress (tfm.checkpoint);
                               removed when the run is stored
    summary.parquet            one row per finished run: run_id, status, p_*, r_*, prov_*
    curves.parquet             every step of every finished run, with run_id
    failures.parquet           one row per failed run: run_id, p_*, error, traceback
    campaign.json              which campaign file made these results: its source, resolved
                               path and sha256; another file with the same name is refused
    .lock                      held (flock) while a `tfm campaign run` works here

Every file is written to a temporary name in the same folder and renamed into place,
so a reader sees either the old file or the new one. A run is done when its run file
exists and its footer names the run id; leftover temporary files are removed when a
campaign resumes. The campaign tables are rebuilt from the run files, in the campaign's
expansion order, so they do not depend on which worker finished first, and again
whenever a run or failure file is rewritten or the campaign file changes.
"""
from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import hashlib
import json
import os
import platform
import time
from pathlib import Path
from typing import Any, Iterable, Iterator

from ..params import Params
from ..results import (code_hash, fields_path_for, loaded_commit, read_checked, read_metadata, tfm_version,
                       write_table)
from .spec import CampaignError, CampaignSpec, Run

TABLES = ("summary", "curves", "failures")
PARAM_PREFIX, RESULT_PREFIX, PROV_PREFIX = "p_", "r_", "prov_"


@dataclasses.dataclass(frozen=True)
class Status:
    """Run ids of a campaign by state, in expansion order."""

    done: list[str]
    failed: list[str]
    pending: list[str]
    flagged: list[str]          # done, but the run raised a warning flag
    stale: list[str] = dataclasses.field(default_factory=list)  # done by other tfm code
    # stored runs and failures of run ids the file no longer expands to (values removed
    # from it): kept on disk, left out of the tables
    extra: list[str] = dataclasses.field(default_factory=list)
    # pending runs whose run file exists but cannot be read, or names another run, or
    # whose field snapshots are gone or cannot be read: they are computed again and the
    # new files replace the damaged ones
    damaged: list[str] = dataclasses.field(default_factory=list)

    @property
    def total(self) -> int:
        return len(self.done) + len(self.failed) + len(self.pending)


def code_here() -> dict[str, Any]:
    """What names the code this process computes with, as a run's provenance does."""
    return {"tfm_version": tfm_version(), "git_commit": loaded_commit(), "code_hash": code_hash()}


def same_code(prov: dict[str, Any], here: dict[str, Any]) -> bool:
    """Whether a stored run's provenance names the code ``here`` computes with: the hash of
    tfm's source files, so that uncommitted edits count and a commit that leaves tfm/ alone
    does not. Runs stored before the hash was recorded: tfm version and commit (a dirty
    tree counting as its commit)."""
    if prov.get("code_hash"):
        return prov["code_hash"] == here["code_hash"]

    def commit(p):
        return (p.get("git_commit") or "").removesuffix("-dirty") or None
    return (prov.get("tfm_version"), commit(prov)) == (here["tfm_version"], commit(here))


class CampaignStore:
    """The files of one campaign under ``root`` (``results/<name>``)."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        self.runs_dir = self.root / "runs"
        self.failures_dir = self.root / "failures"
        self.checkpoints_dir = self.root / "checkpoints"

    @classmethod
    def for_spec(cls, spec: CampaignSpec, results_dir: str | os.PathLike = "results") -> "CampaignStore":
        return cls(Path(results_dir) / spec.name)

    def run_path(self, run_id: str) -> Path:
        return self.runs_dir / f"{run_id}.parquet"

    def failure_path(self, run_id: str) -> Path:
        return self.failures_dir / f"{run_id}.json"

    def checkpoint_path(self, run_id: str) -> Path:
        return self.checkpoints_dir / f"{run_id}.npz"

    def table_path(self, table: str) -> Path:
        return self.root / f"{table}.parquet"

    # ---- exclusive access and crash recovery -------------------------------
    def run_command(self, source) -> str:
        """The command that runs (or resumes) the campaign file ``source`` here: with
        --results-dir unless the results are in results/, where the command puts them."""
        where = self.root.parent
        elsewhere = "" if where.resolve() == Path("results").resolve() else f" --results-dir {where}"
        return f"tfm campaign run {source}{elsewhere}"

    def running(self) -> str | None:
        """Who holds the campaign's lock ('pid N on host'), or None if nobody does."""
        import fcntl

        try:
            fh = open(self.root / ".lock")
        except OSError:
            return None
        with fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return fh.read().strip() or "another process"
            fcntl.flock(fh, fcntl.LOCK_UN)
            return None

    @contextlib.contextmanager
    def lock(self, wait: float = 5.0) -> Iterator[None]:
        """Hold the campaign's lock; a second runner on the same campaign fails after
        ``wait`` seconds. The kernel drops the lock when the holder dies, even by SIGKILL
        (the short wait covers a killed runner's children that are still exiting)."""
        import fcntl

        for folder in (self.runs_dir, self.failures_dir, self.checkpoints_dir):
            if folder.exists() and not folder.is_dir():
                # found before any run, not as a full disk after the first one
                raise CampaignError(f"results-dir: {folder} is a file, where the campaign keeps its "
                                    f"{folder.name}/ folder; move it away")
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            fh = open(self.root / ".lock", "a+")
        except OSError as exc:                # before any run: say where, not a traceback
            raise CampaignError(f"results-dir: cannot write the campaign folder {self.root}: "
                                f"{exc.strerror or exc}") from None
        with fh:
            deadline = time.monotonic() + wait
            while True:
                try:
                    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() > deadline:
                        fh.seek(0)
                        holder = fh.read().strip() or "another process"
                        raise CampaignError(f"{self.root}: {holder} is running this campaign; "
                                            "wait for it or stop it") from None
                    time.sleep(0.05)
            fh.seek(0)
            fh.truncate()
            fh.write(f"pid {os.getpid()} on {platform.node()}")
            fh.flush()
            try:
                yield
            finally:
                fh.truncate(0)
                fcntl.flock(fh, fcntl.LOCK_UN)

    def source_record(self) -> dict[str, Any] | None:
        try:
            return json.loads((self.root / "campaign.json").read_text())
        except (OSError, ValueError):
            return None

    def source_conflict(self, spec: CampaignSpec) -> str | None:
        """Why ``spec`` may not write here, or None. The same file (edited: resume with
        its new runs) or the same content (moved, copied) may; another file may not."""
        rec = self.source_record()
        if rec is None:
            foreign = self.foreign_tables()
            if foreign:
                return (f"{foreign[0]} is not a table of a tfm campaign, and campaign {spec.name!r} would "
                        f"write its {foreign[0].name} there; move {'those files' if len(foreign) > 1 else 'it'} "
                        f"({', '.join(p.name for p in foreign)}) away, or give the campaign another name "
                        "or --results-dir")
            return None
        if rec.get("sha256") == spec.digest:
            return None
        if spec.origin and rec.get("origin") == spec.origin:
            return None
        if not spec.origin and not rec.get("origin") and rec.get("source") == spec.source:
            return None
        return (f"{self.root} holds the results of campaign {rec.get('source')!r} "
                f"(sha256 {str(rec.get('sha256'))[:12]}...), and {spec.source!r} is another campaign with "
                f"the same name {spec.name!r}. Give it its own name, or another --results-dir. If it is that "
                f"file, moved and edited, delete {self.root / 'campaign.json'} and it takes over these "
                "results (runs with the same parameters are reused)")

    def foreign_tables(self) -> list[Path]:
        """The summary, curves and failures tables here that no tfm campaign wrote (their
        footer lacks the campaign record): a campaign would replace them."""
        foreign = []
        for table in TABLES:
            path = self.table_path(table)
            if path.exists():
                try:
                    ours = "campaign" in read_metadata(path)
                except (OSError, ValueError):     # not Parquet at all
                    ours = False
                if not ours:
                    foreign.append(path)
        return foreign

    def claim(self, spec: CampaignSpec) -> None:
        """Record which campaign file writes here (call with the lock held)."""
        conflict = self.source_conflict(spec)
        if conflict:
            raise CampaignError(conflict)
        record = {"name": spec.name, "source": spec.source, "origin": spec.origin, "sha256": spec.digest}
        if self.source_record() != record:
            path = self.root / "campaign.json"
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            tmp.write_text(json.dumps(record, indent=1, sort_keys=True))
            os.replace(tmp, path)

    def clean_temporary(self) -> list[Path]:
        """Remove temporary files left by a killed writer (call with the lock held)."""
        removed = []
        for folder in (self.root, self.runs_dir, self.failures_dir, self.checkpoints_dir):
            for tmp in folder.glob(".*.tmp"):
                tmp.unlink(missing_ok=True)
                removed.append(tmp)
        return removed

    # ---- per-run records ---------------------------------------------------
    def run_metadata(self, run_id: str) -> dict[str, Any] | None:
        """The metadata of a finished run: None unless the run file exists, has a readable
        footer, and is the run it is named after."""
        path = self.run_path(run_id)
        if not path.exists():
            return None
        try:
            meta = read_metadata(path)
        except (OSError, ValueError):        # pyarrow raises ArrowInvalid (a ValueError)
            return None
        return meta if meta.get("run_id") == run_id else None

    def fields_path(self, run_id: str) -> Path:
        """A run's field snapshots (NetCDF4), beside its run file."""
        return fields_path_for(self.run_path(run_id))

    def write_run(self, run: Run, result, fields_bytes: bytes | None = None) -> Path:
        """Store a finished run (a tfm.results.RunResult) atomically; clear its failure.
        Its field snapshots, a file of this machine or ``fields_bytes`` from a remote
        worker, are moved beside the run file first, so a stored run has its fields."""
        if fields_bytes is not None:
            self.runs_dir.mkdir(parents=True, exist_ok=True)
            tmp = self.runs_dir / f".{run.run_id}.fields.nc.{os.getpid()}.recv.tmp"
            tmp.write_bytes(fields_bytes)
            result.fields_path = tmp
        path = result.write_curve(self.run_path(run.run_id))
        self.failure_path(run.run_id).unlink(missing_ok=True)
        self.checkpoint_path(run.run_id).unlink(missing_ok=True)
        return path

    def write_failure(self, run: Run, error: str, trace: str) -> Path:
        record = {"run_id": run.run_id, "params": run.params.to_dict(), "error": error,
                  "traceback": trace, "host": platform.node(),
                  "failed_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        path = self.failure_path(run.run_id)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True))
        os.replace(tmp, path)
        return path

    def read_failure(self, run_id: str) -> dict[str, Any] | None:
        try:
            return json.loads(self.failure_path(run_id).read_text())
        except (OSError, ValueError):
            return None

    def status(self, spec: CampaignSpec) -> Status:
        from ..snapshots import readable as snapshots_readable

        done, failed, pending, flagged, stale, damaged = [], [], [], [], [], []
        here = code_here()
        for run in spec.runs:
            rid = run.run_id
            meta = self.run_metadata(rid)
            if meta is not None and meta.get("fields") and not snapshots_readable(self.runs_dir / meta["fields"]):
                # a run stored with snapshots counts as done only with them (a deleted or
                # truncated file was "done" and only tfm show noticed)
                pending.append(rid)
                damaged.append(rid)
                continue
            if meta is not None:
                done.append(rid)
                if meta.get("summary", {}).get("warnings"):
                    flagged.append(rid)
                if not same_code(meta.get("provenance") or {}, here):
                    stale.append(rid)
            elif self.failure_path(rid).exists():
                failed.append(rid)
            else:
                pending.append(rid)
                if self.run_path(rid).exists():
                    damaged.append(rid)
        return Status(done, failed, pending, flagged, stale, self._not_in(spec), damaged)

    def _not_in(self, spec: CampaignSpec, where=None) -> list[str]:
        """Run ids stored here that ``spec`` does not expand to: in ``where``, (folder, glob)
        pairs, by default the run files and failure records."""
        where = where or ((self.runs_dir, "*.parquet"), (self.failures_dir, "*.json"))
        ids = {r.run_id for r in spec.runs}
        found = {p.stem for d, pat in where if d.is_dir() for p in d.glob(pat) if not p.name.startswith(".")}
        return sorted(found - ids)

    def orphan_checkpoints(self, spec: CampaignSpec) -> list[str]:
        """Run ids of the checkpoints whose runs ``spec`` no longer holds (an edit removed
        their values): nothing would ever continue or remove them."""
        return self._not_in(spec, ((self.checkpoints_dir, "*.npz"),))

    def damaged_note(self, status: Status) -> str | None:
        """What to say about run files that exist but cannot be read, if any."""
        if not status.damaged:
            return None
        metas = {rid: self.run_metadata(rid) for rid in status.damaged}
        files = [rid for rid, meta in metas.items() if meta is None]
        fields = [rid for rid, meta in metas.items() if meta is not None]   # the run file reads
        said = []
        if files:
            n = len(files)
            said.append(f"{n} run file{'s' if n > 1 else ''} in {self.runs_dir} cannot be read as the run "
                        f"{'they are' if n > 1 else 'it is'} named after (damaged or cut short? e.g. "
                        f"{self.run_path(files[0]).name}): {'those runs are' if n > 1 else 'that run is'} pending "
                        "and computed again, the new file replacing the damaged one")
        if fields:
            n, name = len(fields), metas[fields[0]]["fields"]
            state = "gone" if not (self.runs_dir / name).exists() else "unreadable (damaged or cut short?)"
            said.append(f"{n} stored run{'s' if n > 1 else ''} in {self.runs_dir} lack{'' if n > 1 else 's'} "
                        f"the field snapshots {'they' if n > 1 else 'it'} stored (e.g. {name}: {state}): "
                        f"{'those runs are' if n > 1 else 'that run is'} pending and computed again with "
                        "them")
        return "; ".join(said)

    def extra_note(self, status: Status) -> str | None:
        """What to say about stored runs the campaign file no longer has, if any."""
        if not status.extra:
            return None
        n = len(status.extra)
        return (f"{n} stored run{'s' if n > 1 else ''} in {self.root} {'are' if n > 1 else 'is'} not in the "
                f"campaign file now (values removed from it, a [base] value changed, or a height map's content "
                f"changed: its hash is in the run id?): kept on disk in {self.runs_dir.name}/ or "
                f"{self.failures_dir.name}/, and left out of the tables when they are next built; put the values "
                "(or the map) back to have them in the tables again")

    # ---- campaign tables ---------------------------------------------------
    def write_tables(self, spec: CampaignSpec, status: Status | None = None) -> bool:
        """Assemble summary, curves and failures from the run files; False if already current."""
        status = status or self.status(spec)
        record = self._record(spec, status)
        if self._tables_current(record):
            return False
        import pandas as pd

        by_id = {r.run_id: r for r in spec.runs}
        rows, curves = [], []
        for rid in status.done:
            path = self.run_path(rid)
            meta = read_metadata(path)
            summary = meta["summary"]
            fields = meta.get("fields")
            rows.append({"run_id": rid, "status": "flagged" if summary.get("warnings") else "ok",
                         # field snapshots of the run, relative to the campaign folder
                         "fields_path": f"{self.runs_dir.name}/{fields}" if fields else None,
                         **param_columns(by_id[rid].params),
                         **{RESULT_PREFIX + k: v for k, v in summary.items()},
                         **{PROV_PREFIX + k: v for k, v in meta.get("provenance", {}).items()}})
            try:
                curve = read_checked(path)
            except (OSError, ValueError) as exc:     # pyarrow's errors derive from these
                raise CampaignError(f"{path}: the stored run {rid} cannot be read ({exc}); the file is "
                                    "damaged (a crash of the machine, a bad copy): delete it and run the "
                                    "campaign again to recompute that run") from None
            curve.insert(0, "run_id", rid)
            curves.append(curve)
        fails = []
        for rid in status.failed:
            rec = self.read_failure(rid) or {}
            fails.append({"run_id": rid, **param_columns(by_id[rid].params),
                          "error": rec.get("error", ""), "traceback": rec.get("traceback", ""),
                          "host": rec.get("host", ""), "failed_at": rec.get("failed_at", "")})
        from ..units import COLUMN_UNITS
        # per row, p_units says which system applies (r_length_unit, r_force_unit too)
        extra = {"campaign": record, "units": COLUMN_UNITS}
        summary_df = _typed_frame(rows, ["run_id", "status", "fields_path"] + param_names())
        curves_df = (pd.concat(curves, ignore_index=True) if curves
                     else pd.DataFrame({"run_id": pd.Series([], dtype=object)}))
        fail_cols = ["run_id"] + param_names() + ["error", "traceback", "host", "failed_at"]
        failures_df = _typed_frame(fails, fail_cols)
        # the summary last: its metadata is what says the tables are current
        write_table(curves_df, self.table_path("curves"), extra=extra)
        write_table(failures_df, self.table_path("failures"), extra=extra)
        write_table(summary_df, self.table_path("summary"), extra=extra)
        return True

    def _record(self, spec: CampaignSpec, status: Status) -> dict[str, Any]:
        # The ids alone do not say the tables are current: --rerun-stale rewrites runs, a
        # failed retry rewrites its record, and an edited file changes p_* (allow is not in
        # the run id). So the record also holds the file's digest and the run files' stats.
        return {"name": spec.name, "description": spec.description, "sha256": spec.digest,
                "run_ids": status.done, "failed": status.failed, "files": self._files_digest(status)}

    def tables_current(self, spec: CampaignSpec, status: Status | None = None) -> bool:
        """Whether summary, curves and failures hold the stored runs as they are now (a
        campaign process killed after storing a run has not rebuilt them)."""
        return self._tables_current(self._record(spec, status or self.status(spec)))

    def tables_behind(self, spec: CampaignSpec, status: Status | None = None) -> str | None:
        """Why the tables do not hold the stored runs as they are now (None: they do)."""
        status = status or self.status(spec)
        record = self._record(spec, status)
        if self._tables_current(record):
            return None
        try:
            written = read_metadata(self.table_path("summary")).get("campaign")
        except (OSError, ValueError):
            written = None
        if not isinstance(written, dict):
            return "no readable summary table"
        if written.get("sha256") != record["sha256"]:
            return "the campaign file has changed since they were written, and they hold the runs of the file as it was"
        then = set(written.get("run_ids") or []) | set(written.get("failed") or [])
        now = set(record["run_ids"]) | set(record["failed"])
        # first: the file expands to other runs (a height map's content put back makes the
        # runs of the old content current again, and they were not "stored after")
        if then - now and (then - now) <= set(status.extra):
            # the run files are there: the file expands to other run ids now
            return ("they hold runs the campaign file no longer expands to (stored runs whose parameters, "
                    "or height map's content, are no longer those of the file)")
        if now - then:
            return "runs were stored after they were written, by a campaign process that stopped before rebuilding them"
        if then - now:
            return "they hold runs whose files are now gone or damaged (those runs are pending again)"
        if (written.get("run_ids"), written.get("failed")) != (record["run_ids"], record["failed"]):
            return "runs have moved between done and failed since they were written"
        return "run files have changed since they were written (or were copied without their times)"

    def _files_digest(self, status: Status) -> str:
        """A digest of the run and failure files as they are now: size and mtime (one stat
        each, no reading; every write replaces the file by a new one, with a new mtime).
        Not the inode: a copy kept with its times (cp -a, rsync -a, a backup) was called
        stale."""
        digest = hashlib.sha256()
        for path in [self.run_path(r) for r in status.done] + [self.failure_path(r) for r in status.failed]:
            try:
                st = path.stat()
                digest.update(f"{path.name} {st.st_size} {st.st_mtime_ns}\n".encode())
            except OSError:
                digest.update(f"{path.name} missing\n".encode())
        return digest.hexdigest()

    def _tables_current(self, record: dict[str, Any]) -> bool:
        try:
            return all(read_metadata(self.table_path(t)).get("campaign") == record for t in TABLES)
        except (OSError, ValueError):
            return False

    def load(self, table: str) -> pd.DataFrame:
        import pandas as pd

        path = self.table_path(table)
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such table; run the campaign first "
                                    "(tfm campaign run FILE)")
        return read_checked(path)


# ---- parameter columns with stable types ------------------------------------
def param_names() -> list[str]:
    return [PARAM_PREFIX + n for n in Params.field_names()]


def _param_kinds() -> dict[str, str]:
    """float, int or str per parameter, from the record's annotations. A field that may
    hold a string (max_indent: a number or "auto") is stored as a string column."""
    kinds = {}
    for f in dataclasses.fields(Params):
        t = str(f.type)
        kinds[f.name] = "str" if "str" in t else "float" if "float" in t else "int" if "int" in t else "str"
    return kinds


def param_columns(params: Params) -> dict[str, Any]:
    kinds = _param_kinds()
    out = {}
    for name, value in params.to_dict().items():
        if value is not None and kinds[name] == "str":
            value = str(value)
        out[PARAM_PREFIX + name] = value
    return out


def _typed_frame(rows: list[dict[str, Any]], leading: Iterable[str]) -> pd.DataFrame:
    """A frame whose column types do not depend on the values: parameters typed from the
    record, ints that may be None as nullable Int64, strings as object."""
    import pandas as pd

    leading = list(leading)
    columns = leading + [c for row in rows for c in row if c not in leading]
    columns = list(dict.fromkeys(columns))
    kinds = {PARAM_PREFIX + k: v for k, v in _param_kinds().items()}
    data = {}
    for col in columns:
        values = [row.get(col) for row in rows]
        kind = kinds.get(col) or _infer_kind(values)
        if kind == "float":
            data[col] = pd.Series([float("nan") if v is None else v for v in values], dtype="float64")
        elif kind == "int":
            data[col] = pd.Series(values, dtype="Int64" if None in values or not values else "int64")
        elif kind == "bool":
            data[col] = pd.Series(values, dtype="boolean" if None in values else "bool")
        else:
            data[col] = pd.Series(values, dtype=object)
    return pd.DataFrame(data, columns=columns)


def _infer_kind(values: list[Any]) -> str:
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return "bool"
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return "int"
    if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return "float"
    return "str"
