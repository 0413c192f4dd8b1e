"""Checkpoints: a run killed mid-curve continues from its last saved step.

A campaign stores finished runs only, so a crash, a lost session or a cluster's time limit
used to cost the whole of a run in progress, and the finest runs take hours. With a
checkpoint file, the displacement-controlled protocol saves after a finished step, at
most every ``every`` seconds, everything the next step reads: the contact state's arrays
(contact set, F, u, the warm start's slopes; ``ContactState.carried``), the curve so far
and its counters. A resumed run goes on from the next step and ends with the same curve,
bit for bit, as a run that was never stopped (tests/test_checkpoint.py).

SIGINT (Ctrl-C) or SIGTERM (a cluster's time limit, `kill`) during a checkpointed run is
acted on after the step in progress: the state is saved, then the signal goes to the
handler that was there before (KeyboardInterrupt, the process's end, a campaign's own), so
a stopped run loses no finished step. A second signal acts at once (StopRequest). A run
without a checkpoint waits for the end of its step in progress the same way, with nothing
to save (tfm.protocol.run).

A checkpoint serves only the run it was written for (the run id hashes every parameter)
and the same engine (a hash of tfm's source files): other code could not promise the same
bits, so the run then starts afresh, with a warning (CheckpointWarning; its provenance
says so in ``checkpoint_set_aside``). Force control (its bisection keeps
copies of states) and runs with field snapshots (a NetCDF stream) are not checkpointed.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import signal
import threading
import time
import warnings
import zipfile
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .config import CHECKPOINT_EVERY
from .params import ParameterError
from .progress import say
from .results import code_hash

FORMAT = 1
DONE = "done"      # the phase of a checkpoint saved after the curve's last step

class CheckpointWarning(UserWarning):
    """A checkpoint that cannot serve its run was set aside; the run starts afresh. Not a
    RunWarning: those flag suspect numbers and are silenced where the summary records them,
    while this one says that saved work is not used."""


def why_not(p) -> str | None:
    """Why the run ``p`` cannot have a checkpoint, or None if it can."""
    if p.control == "displacement" and p.snapshots == "none":
        return None
    return (f"only displacement-controlled runs without field snapshots are checkpointed (this one: "
            f"control={p.control!r}, snapshots={p.snapshots!r})")


def check_every(every, name: str = "checkpoint_every") -> float:
    """The interval between saves in seconds; anything but a number >= 0 is refused."""
    if isinstance(every, bool) or not isinstance(every, (int, float)):
        raise ParameterError(f"{name}: expected a number of seconds >= 0, got {every!r}")
    if not every >= 0:
        raise ParameterError(f"{name}: must be >= 0 seconds, got {every!r}")
    return float(every)


_PATIENT = False


def stop_patiently() -> None:
    """In this process a second SIGTERM does not stop a run at once: a campaign's pool
    worker gets its SIGTERMs from the campaign and from the pool, which terminates every
    worker when the first one exits. That is no user insisting, and it stopped a worker
    before it had saved its step in progress."""
    global _PATIENT
    _PATIENT = True


class StopRequest:
    """SIGINT and SIGTERM while a run computes: remembered, and acted on at the next step
    boundary (``pending``), where a checkpointed run saves its state in ``path`` (None: a
    run without a checkpoint) and calls ``deliver``.
    Installed only in the main thread (only it may handle signals) and only for signals
    that are not ignored (a campaign's pool workers ignore SIGINT: their campaign decides).
    A second signal stops at once, except after ``stop_patiently()``."""

    def __init__(self, path, until: str = "after the step in progress"):
        self.path = path
        self.until = until
        self.signum: int | None = None
        self._saved: dict = {}

    @property
    def pending(self) -> bool:
        return self.signum is not None

    def __call__(self, signum, frame):
        if self.signum is not None:        # a second signal: at once, unless patient
            if not _PATIENT:
                self.signum = signum
                self.deliver()
            return
        self.signum = signum
        why = "" if self.path is None else f", to save the run's state in {self.path}"
        if _PATIENT:                       # a campaign's worker: its campaign sent the signal
            say(f"tfm: stopping {self.until}{why}")
        else:
            say(f"tfm: {signal.Signals(signum).name}: stopping {self.until}{why} (a second signal stops at once)")

    @contextlib.contextmanager
    def installed(self):
        # a campaign's worker with nothing to save: its campaign's SIGTERM stops it at once
        if threading.current_thread() is threading.main_thread() and not (_PATIENT and self.path is None):
            for sig in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self._saved[sig] = signal.signal(sig, self)
        try:
            yield self
        finally:
            self._restore()

    def _restore(self) -> None:
        for sig, handler in self._saved.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        self._saved = {}

    def deliver(self) -> None:
        """The remembered signal, to the handlers that were there before (raises
        KeyboardInterrupt for Ctrl-C, ends the process for SIGTERM's default)."""
        signum, self.signum = self.signum, None
        dies = self._saved.get(signum) in (signal.SIG_DFL, None)
        self._restore()
        if dies and signum != signal.SIGINT:
            # the process ends without unwinding: the half-written snapshots (tens of MB
            # each, hidden beside the table or in /tmp) would stay
            from .snapshots import remove_live_temporaries
            remove_live_temporaries()
        signal.raise_signal(signum)


@dataclass
class Resume:
    """A saved run: the state to restore, the curve so far, where the protocol stood."""

    carried: dict
    out: object            # tfm.solver.CurveResult
    phase: str             # "load" or "unload": the phase of the last finished step
    j: int                 # that step's number within its phase (1-based)
    elapsed: float         # the run's compute time so far (s)


class Checkpoint:
    """The checkpoint file of one run (``path``, an .npz), saved at most every ``every``
    seconds; ``every = 0`` saves after every step (tests)."""

    def __init__(self, path: str | os.PathLike, run_id: str, every: float = CHECKPOINT_EVERY):
        self.path = Path(path)
        self.run_id = run_id
        self.every = check_every(every)
        self._last = time.monotonic()
        self.resumed_at = None     # the step a loaded checkpoint continues from
        self.set_aside = None      # why a checkpoint found here was not used
        self.save_when_done = False  # also save the finished curve (phase DONE)
        self.failed_saves = 0      # saves that could not be written (try_save)
        self.save_error = ""       # the first one's reason
        self.started_at = None     # when the run first started (saved; a resumed run keeps it)

    # ---- reading -------------------------------------------------------------
    def saved_run_id(self) -> str | None:
        """The run id the file here was saved for (None: no file, or not a readable checkpoint)."""
        return (read_meta(self.path) or {}).get("run_id")

    def foreign(self) -> str | None:
        """What the file here holds if it is not this run's saved state (another run's, or
        no checkpoint at all), None if there is no file or it is this run's."""
        if not self.path.exists():
            return None
        owner = self.saved_run_id()
        if owner == self.run_id:
            return None
        return f"the saved state of another run ({owner})" if owner else "a file that is not a readable checkpoint"

    def load(self) -> Resume | None:
        """The saved run, or None (no file, another run or engine, unreadable: warned)."""
        from .solver import CurveResult, StepRecord

        if not self.path.exists():
            return None
        with open(self.path, "rb") as fh:
            if fh.read(2) != b"PK":        # NumPy calls any other file "pickled data"
                return self._refuse("cannot be read (not an .npz archive)")
        try:
            # our own file object: np.load leaves its own open when the archive is damaged
            with open(self.path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
                arrays = {key: z[key] for key in z.files}
            meta = json.loads(str(arrays.pop("meta")))
        except UNREADABLE as exc:          # a truncated or damaged file too (BadZipFile)
            return self._refuse(f"cannot be read ({type(exc).__name__}: {exc})")
        why = unusable(meta, self.run_id)
        if why:
            return self._refuse(why)
        out = CurveResult(**meta["counters"])
        cols = {f.name: arrays.pop(f"curve.{f.name}") for f in fields(StepRecord)}
        out.steps = [StepRecord(*(_plain(cols[f.name][i]) for f in fields(StepRecord)))
                     for i in range(len(cols["step"]))]
        carried = {name: _unflatten(name, value, arrays) for name, value in meta["carried"].items()}
        self.resumed_at = len(out.steps)
        self.started_at = meta.get("started_at", self.started_at)    # the first process's start
        return Resume(carried, out, meta["phase"], int(meta["j"]), float(meta["elapsed"]))

    def _refuse(self, why: str) -> None:
        self.set_aside = f"checkpoint {self.path} {why}; the run starts afresh"
        warnings.warn(f"run {self.run_id}: {self.set_aside}", CheckpointWarning, stacklevel=3)
        return None

    # ---- writing -------------------------------------------------------------
    def step_done(self, state, out, phase: str, j: int, elapsed: float) -> None:
        """Called after every finished step; saves if ``every`` seconds have passed."""
        if time.monotonic() - self._last >= self.every:
            self.try_save(state, out, phase, j, elapsed)

    def try_save(self, state, out, phase: str, j: int, elapsed: float) -> bool:
        """``save``, but a write that fails (a full disk, a quota) warns and lets the run go
        on, trying again ``every`` seconds later: a checkpoint only guards the curve, and
        its OSError used to end the run and lose the whole curve, even when the table
        would have fit. The last checkpoint saved, if any, stays (saves are atomic)."""
        try:
            self.save(state, out, phase, j, elapsed)
            return True
        except OSError as exc:
            self._last = time.monotonic()
            if not self.failed_saves:
                self.save_error = str(exc.strerror or exc)
                warnings.warn(f"run {self.run_id}: {exc}; the run goes on without it"
                              + (f" and tries again every {self.every:g} s" if phase != DONE else ""),
                              CheckpointWarning, stacklevel=2)
            self.failed_saves += 1
            return False

    def save(self, state, out, phase: str, j: int, elapsed: float) -> None:
        """Write the state atomically: a temporary file in the same folder, then renamed."""
        from .solver import StepRecord

        arrays, carried = {}, {}
        for name, value in state.carried().items():
            carried[name] = _flatten(name, value, arrays)
        for f in fields(StepRecord):
            arrays[f"curve.{f.name}"] = np.array([getattr(s, f.name) for s in out.steps])
        counters = {f.name: getattr(out, f.name) for f in fields(out) if f.name != "steps"}
        meta = {"format": FORMAT, "run_id": self.run_id, "code": code_hash(), "phase": phase, "j": int(j),
                "steps": len(out.steps), "elapsed": float(elapsed), "counters": counters, "carried": carried,
                "started_at": self.started_at,
                "written_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        arrays["meta"] = np.array(json.dumps(meta))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
            os.replace(tmp, self.path)
        except OSError as exc:             # a full disk: say which file, not only "File too large"
            raise OSError(exc.errno, f"cannot save the checkpoint {self.path}: {exc.strerror or exc}") from exc
        finally:
            tmp.unlink(missing_ok=True)    # a save stopped by a second Ctrl-C left it
        self._last = time.monotonic()

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


# what reading a damaged checkpoint raises: a truncated archive or a flipped bit gives
# zipfile.BadZipFile ("Bad CRC-32"), which is none of the others
UNREADABLE = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile)


def unusable(meta: dict, run_id: str) -> str | None:
    """Why a checkpoint with metadata ``meta`` cannot continue run ``run_id``, or None."""
    if meta.get("format") != FORMAT:
        return f"has format {meta.get('format')!r}, this engine reads {FORMAT}"
    if meta.get("run_id") != run_id:
        return f"belongs to run {meta.get('run_id')!r}"
    if meta.get("code") != code_hash():
        return "was written by another version of tfm's source, which cannot promise the same numbers"
    return None


def read_meta(path: str | os.PathLike) -> dict | None:
    """A checkpoint's metadata (run_id, steps done, phase, elapsed, written_at), or None
    if it cannot be read."""
    try:
        with open(path, "rb") as fh:
            if fh.read(2) != b"PK":        # not an .npz archive (np.load would give an array)
                return None
            fh.seek(0)
            with np.load(fh, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
        meta.pop("carried", None)
        return meta
    except UNREADABLE + (AttributeError,):      # AttributeError: metadata that is not a mapping
        return None


# A carried value is None, a number, an array, or a tuple of numbers and arrays: numbers
# go to the JSON metadata (repr round-trips a float64 exactly), arrays to the .npz.
def _flatten(name, value, arrays):
    if isinstance(value, tuple):
        return {"tuple": [_flatten(f"{name}.{i}", v, arrays) for i, v in enumerate(value)]}
    if isinstance(value, np.ndarray):
        arrays[f"state.{name}"] = value
        return {"array": f"state.{name}"}
    return {"value": _plain(value)}


def _unflatten(name, entry, arrays):
    if "tuple" in entry:
        return tuple(_unflatten(f"{name}.{i}", e, arrays) for i, e in enumerate(entry["tuple"]))
    if "array" in entry:
        return np.array(arrays[entry["array"]])          # a writable, contiguous copy
    return entry["value"]


def _plain(v):
    """A numpy scalar as the Python number or string it holds."""
    return v.item() if isinstance(v, np.generic) else v
