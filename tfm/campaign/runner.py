"""Run a campaign: in this process, over a local process pool, or on a Dask cluster.

Each worker gets ``max(1, cores // workers)`` Numba threads (and as many scipy.fft
workers, through NUMBA_NUM_THREADS, see ``tfm.config.fft_workers``), so two jobs on a
two-core machine run one thread each. Results do not depend on the thread count: the
engine's reductions use fixed blocks (``tfm.config.REDUCTION_BLOCK``).

Workers only compute; this process writes every file (``CampaignStore``), so a Dask
cluster needs no shared file system, and a run is either fully stored or not at all.
A run that raises is recorded as a failure (parameters and traceback) and the others go on.
SIGINT or SIGTERM stops the campaign between two stores: the runs that finished are
stored, the runs in flight are stopped (their checkpoints stay), and CampaignInterrupted
says how to resume.
"""
from __future__ import annotations

import contextlib
import math
import os
import signal
import sys
import threading
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from ..config import CHECKPOINT_EVERY
from ..guards import GuardError, check_cost, direct_cost_note, n_springs
from ..params import ParameterError
from ..progress import counted
from .spec import CampaignError, CampaignSpec, Run, load_spec
from .store import CampaignStore


@dataclass
class Outcome:
    """What a worker sends back: a RunResult, or the error and its traceback."""

    result: Any = None
    error: str = ""
    traceback: str = ""
    fields_bytes: bytes | None = None   # field snapshots sent back by a remote (Dask) worker


class CampaignStorageError(CampaignError):
    """Computed runs or tables that could not be stored (a full or read-only disk): exit
    status 1, as `tfm run`'s for an output not written after the run (2 is bad input,
    before any computation)."""

    exit_status = 1


class CampaignInterrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped a campaign after it stored every run that had finished."""

    def __init__(self, message: str, signum: int = signal.SIGINT):
        super().__init__(message)
        self.signum = signum


class _Stop:
    """SIGINT and SIGTERM while a campaign runs: remembered and acted on between stores, so
    that no finished run is lost to an interrupted write. Raised (KeyboardInterrupt) at once
    only while this process computes a run itself (serial; the run's checkpoint stays). A
    second signal ends the process outright (every file is written atomically)."""

    def __init__(self):
        self.signum: int | None = None
        self.computing = False

    def __call__(self, signum, frame):
        self.signum = signum
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        if self.computing:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def installed(self):
        if threading.current_thread() is not threading.main_thread():
            yield self                   # only the main thread may handle signals
            return
        saved = {sig: signal.signal(sig, self) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for sig, handler in saved.items():
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)


POLL = 0.2      # seconds between looks at a stop request while waiting for runs
NO_WORKERS_NOTE = 30.0   # seconds without any Dask worker before the campaign says so


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    return max(1, (cores or available_cores()) // max(1, workers))


def run_campaign(spec_or_path, jobs: int = 1, scheduler=None, quiet: bool = False,
                 results_dir: str | os.PathLike = "results", retry_failed: bool = True,
                 rerun_stale: bool = False, only=None,
                 checkpoint_every: float | None = CHECKPOINT_EVERY, left_out_as: str = "not selected") -> Path:
    """Run every run of a campaign that is not stored yet; return ``results_dir/<name>``.

    ``jobs`` > 1 uses a local process pool; ``scheduler`` (an address such as
    ``tcp://host:8786``, or a ``distributed.Client``) runs on a Dask cluster instead.
    Finished runs are skipped, so calling it again after a crash resumes the campaign.
    Failed runs are tried again unless ``retry_failed=False``. Runs stored by other
    tfm source code (prov_code_hash) are kept (with a warning) unless ``rerun_stale=True``:
    the run id hashes the parameters, not the code. ``only`` (run ids or runs, e.g. from select_runs) limits
    what is computed now (the closing line counts the others as ``left_out_as``); the
    campaign tables still cover every stored run.

    On this machine (serial or process pool) a displacement-controlled run without field
    snapshots saves its state every ``checkpoint_every`` seconds in ``checkpoints/``
    (tfm.checkpoint; None: never, 0: after every step): after a crash it continues from
    there, not from its first step. Dask workers may not share this file system, so they do not checkpoint.

    SIGINT or SIGTERM (in the main thread) stores the runs that have finished, stops the
    others (keeping their checkpoints), writes the tables and raises CampaignInterrupted.
    """
    spec = spec_or_path if isinstance(spec_or_path, CampaignSpec) else load_spec(spec_or_path)
    if not isinstance(jobs, int) or jobs < 1:
        raise CampaignError(f"jobs: must be a whole number >= 1, got {jobs!r}")
    if scheduler is not None:
        # options of this machine's runs that a Dask cluster would silently not use
        if jobs != 1:
            raise CampaignError(f"jobs: {jobs} applies to a local pool, not to a Dask cluster (--scheduler): "
                                "the cluster's workers set the parallelism")
        if checkpoint_every not in (CHECKPOINT_EVERY, None):
            raise CampaignError("checkpoint-every: Dask workers do not checkpoint (they may not share this "
                                "disk); leave it at its default with --scheduler")
    if checkpoint_every is not None:
        from ..checkpoint import check_every

        try:
            checkpoint_every = check_every(checkpoint_every, "checkpoint-every")
        except ParameterError as exc:
            raise CampaignError(f"{exc} (or None: no checkpoints)") from None
    # an unreachable cluster is refused before the campaign's folder is claimed
    client = _dask_client(scheduler) if scheduler is not None else None
    try:
        return _run_claimed(spec, client, jobs, quiet, results_dir, retry_failed, rerun_stale, only,
                            checkpoint_every, left_out_as)
    finally:
        if client is not None and client is not scheduler:
            client.close()


def _run_claimed(spec, client, jobs, quiet, results_dir, retry_failed, rerun_stale, only,
                 checkpoint_every, left_out_as) -> Path:
    """run_campaign from the claim of its folder on (``client``: a connected Dask client)."""
    store = CampaignStore.for_spec(spec, results_dir)
    fresh = not store.root.exists()
    try:
        with store.lock():
            return _run_locked(spec, store, client, jobs, quiet, retry_failed, rerun_stale, only,
                               checkpoint_every, left_out_as)
    except CampaignError:
        if fresh and not store.source_record():
            # refused before the claim: leave no folder that names this campaign
            with contextlib.suppress(OSError):
                (store.root / ".lock").unlink(missing_ok=True)
                store.root.rmdir()
        raise


def _run_locked(spec, store, client, jobs, quiet, retry_failed, rerun_stale, only,
                checkpoint_every, left_out_as) -> Path:
    """_run_claimed with the campaign's lock held: the checks that may refuse the campaign,
    then the claim of its folder, the runs and the tables."""
    conflict = store.source_conflict(spec)
    if conflict:
        raise CampaignError(conflict)
    store.clean_temporary()
    status = store.status(spec)
    redo = set(status.pending) | (set(status.failed) if retry_failed else set())
    if status.stale:
        if rerun_stale:
            redo |= set(status.stale)
        else:
            print(f"warning: campaign {spec.name}: {counted(len(status.stale), 'stored run')} "
                  f"{'was' if len(status.stale) == 1 else 'were'} computed "
                  "by other tfm source code (prov_code_hash, a hash of its files; see prov_git_commit); "
                  "they are kept. Use --rerun-stale to recompute them.", file=sys.stderr)
    extra = store.extra_note(status)
    if extra:                          # even with quiet: their rows leave the tables
        print(f"campaign {spec.name}: {extra}", file=sys.stderr)
    damaged = store.damaged_note(status)
    if damaged:                        # even with quiet: stored data were lost
        print(f"warning: campaign {spec.name}: {damaged}", file=sys.stderr)
    # done and kept, selected or not; a stale run left out by ``only`` is "not selected"
    # only (it was counted twice: "2 runs done, 6 already done, 6 not selected" of 8)
    already = len(set(status.done) - redo)
    left_out = ""                       # runs to compute outside ``only``, said as left_out_as
    if only is not None:                 # run ids, or the Run records select_runs returns
        chosen = {getattr(r, "run_id", r) for r in only}
        n_out = len(redo - chosen)
        left_out = f"{n_out} {left_out_as}" if n_out else ""
        redo &= chosen
    todo = [run for run in spec.runs if run.run_id in redo]
    if todo and client is None:
        _check_memory(spec, todo, min(jobs, len(todo)))
    _check_cost(spec, todo)
    costly = [(run, note) for run in todo if (note := direct_cost_note(run.params))]
    if costly:                           # even with quiet: hours may be at stake
        run, note = max(costly, key=lambda rn: n_springs(rn[0].params))
        print(f"campaign {spec.name}: {len(costly)} run{'s' if len(costly) > 1 else ''} of the direct sum "
              f"may take long; the largest, run {run.index}: {note}", file=sys.stderr)
    from ..snapshots import size_note
    sized = [(run, note) for run in todo if run.params.snapshots != "none" and (note := size_note(run.params))]
    if sized:                            # even with quiet: a full disk may be at stake
        run, note = sized[0]
        print(f"campaign {spec.name}: {len(sized)} run{'s' if len(sized) > 1 else ''} with field snapshots to "
              f"note; run {run.index}: {note}", file=sys.stderr)
    noted = [run for run in todo if run.notes]
    if noted:                            # warnings stay with quiet (its help says so)
        for run in noted[:3]:
            print(f"warning: campaign {spec.name}: run {run.index}: {'; '.join(run.notes)}", file=sys.stderr)
        if len(noted) > 3:
            print(f"warning: campaign {spec.name}: {len(noted) - 3} more runs with such notes "
                  "(they are flagged in the summary)", file=sys.stderr)
    store.claim(spec)                     # after every check that may refuse it
    stop, handled = _Stop(), set()
    with stop.installed():
        if todo:
            ckpt = (store, checkpoint_every)
            if client is not None:
                outcomes = _run_dask(todo, client, stop)
            elif jobs > 1 and len(todo) > 1:
                outcomes = _run_pool(todo, jobs, ckpt, stop)
            else:
                outcomes = _run_serial(todo, ckpt, stop)
            try:
                _consume(spec, store, todo, outcomes, skipped=already, quiet=quiet,
                         handled=handled, left_out=left_out)
            except KeyboardInterrupt:
                if stop.signum is None:
                    raise
        elif not quiet:
            # runs not done and not selected: they are not "done" (tfm limit's kept points)
            print(f"campaign {spec.name}: nothing to run, {already} of {len(spec.runs)} runs "
                  f"already done" + (f", {left_out}" if left_out else "")
                  + f" -> {store.root}", file=sys.stderr)
        try:
            store.write_tables(spec)
        except OSError as exc:
            raise CampaignStorageError(
                f"cannot write the campaign's tables in {store.root}: {exc.strerror or exc}. Every run is "
                f"stored in {store.runs_dir}; free space or fix the permissions, then run "
                f"{_again(spec, store)} again to write them") from None
    if stop.signum is not None:
        left = [r for r in todo if r.run_id not in handled]
        if left:
            raise _interrupted(spec, store, left, stop.signum, client)
        # the signal came after the last run was stored and the tables written: complete
        print(f"campaign {spec.name}: a stop signal came after every run had finished; the campaign "
              "is complete", file=sys.stderr)
    return store.root


def _interrupted(spec, store, unfinished: list[Run], signum: int, client=None) -> CampaignInterrupted:
    kept = sum(store.checkpoint_path(r.run_id).exists() for r in unfinished)
    # a Dask campaign resumed without --scheduler would run locally, one run at a time
    again = _again(spec, store, client)
    return CampaignInterrupted(
        f"campaign {spec.name} interrupted by {signal.Signals(signum).name}: the finished runs are "
        f"stored in {store.root}; {len(unfinished)} runs did not finish, {kept} of them with a checkpoint "
        f"to continue from. To resume, run {again} again", signum)


def _check_memory(spec, todo: list[Run], workers: int) -> None:
    """Refuse, before any run starts, runs that cannot fit in this machine's memory when
    ``workers`` of the largest run at once (unless their record allows 'memory')."""
    from ..guards import available_memory, estimate_memory

    have = available_memory()
    big = max((r for r in todo if "memory" not in r.params.allow.split(",")),
              key=lambda r: estimate_memory(r.params), default=None)
    if have is None or big is None:
        return
    need = estimate_memory(big.params) * workers
    if need > have:
        raise CampaignError(f"{spec.source}: run {big.index} {big.run_id} needs about "
                            f"{estimate_memory(big.params) / 2**30:.2f} GiB, {need / 2**30:.2f} GiB for "
                            f"{workers} at once, but {have / 2**30:.2f} GiB is available. Use fewer --jobs, "
                            "a coarser spacing, or allow = \"memory\" for these runs")


def _check_cost(spec, todo: list[Run]) -> None:
    """Refuse, before any run starts, direct-sum runs estimated at more than a week (the
    ``cost`` guard; each used to start and fail as a run of its own, among the others)."""
    for run in todo:
        try:
            check_cost(run.params)
        except GuardError as exc:
            # the guard's own advice names the command line's flag: a campaign's is its file
            raise CampaignError(f"{spec.source}: run {run.index} {run.run_id}: {exc.reason or exc}. Give the "
                                "run allow = \"cost\" in the campaign file to run it anyway") from None


def _consume(spec, store, todo, outcomes: Iterator[tuple[Run, Outcome]], skipped: int, quiet: bool,
             handled: set[str], left_out: str = "") -> None:
    """Store each outcome as it comes; ``handled`` collects the ids stored, also when the
    outcomes stop early (an interrupted campaign). ``skipped`` runs were done before,
    ``left_out`` says how many are not done and not selected (for the closing line)."""
    from .store import code_here, same_code

    bar = _progress(spec.name, len(todo), quiet)
    failed = 0
    here, other_code = code_here(), 0
    try:
        for run, outcome in outcomes:
            if outcome.result is not None:
                _storing(run, store, spec, lambda: store.write_run(run, outcome.result, outcome.fields_bytes))
                prov = outcome.result.provenance
                set_aside = prov.get("checkpoint_set_aside")
                if set_aside:              # even with quiet: a warning
                    bar.write(f"warning: run {run.index} {run.run_id}: {set_aside}", file=sys.stderr)
                if prov.get("checkpoint_failed_saves"):
                    # even with quiet: the run had no protection against a crash
                    bar.write(f"warning: run {run.index} {run.run_id}: {prov['checkpoint_failed_saves']} "
                              f"checkpoint save(s) failed ({prov.get('checkpoint_save_error', '')}); the run "
                              "went on without one", file=sys.stderr)
                if not same_code(prov, here):      # the test that makes a stored run stale
                    other_code += 1
                    if other_code == 1:    # once: a whole cluster usually runs the same code
                        bar.write(f"warning: campaign {spec.name}: run {run.index} was computed by other tfm "
                                  f"source code (prov_code_hash {prov.get('code_hash', '')[:12]}, here "
                                  f"{here['code_hash'][:12]}): "
                                  "the Dask workers run another version of tfm. Its results are stored and "
                                  "count as stale; run the workers from this code", file=sys.stderr)
            else:
                failed += 1
                _storing(run, store, spec, lambda: store.write_failure(run, outcome.error, outcome.traceback))
                if not quiet:
                    bar.write(f"run {run.index} {run.run_id} failed: {outcome.error}", file=sys.stderr)
            handled.add(run.run_id)
            bar.update(1)
            bar.set_postfix(failed=failed, refresh=False)
    finally:
        outcomes.close()
        bar.close()
    if other_code > 1:
        print(f"warning: campaign {spec.name}: {counted(other_code, 'run')} were computed by other tfm source code "
              "(see prov_code_hash)", file=sys.stderr)
    if not quiet and len(handled) == len(todo):
        print(f"campaign {spec.name}: {counted(len(todo) - failed, 'run')} done, {failed} failed, "
              f"{skipped} already done" + (f", {left_out}" if left_out else "")
              + f" -> {store.root}", file=sys.stderr)


def _again(spec, store, client=None) -> str:
    """How to run the campaign again: its command (on the same Dask cluster, given its
    ``client``), or, for a campaign made in Python, the same call."""
    if not spec.origin:
        return "the same call"
    address = getattr(getattr(client, "scheduler", None), "address", None) if client is not None else None
    return f"`{store.run_command(spec.source)}{f' --scheduler {address}' if address else ''}`"


def _storing(run, store, spec, write) -> None:
    """``write()`` the outcome of ``run``; a disk that refuses it (full, read-only) stops the
    campaign with what is safe and what to do, not a traceback."""
    try:
        write()
    except OSError as exc:
        kept = store.checkpoint_path(run.run_id).exists()
        raise CampaignStorageError(
            f"cannot store run {run.index} {run.run_id} in {store.root}: {exc.strerror or exc}"
            f"{f' ({exc.filename})' if getattr(exc, 'filename', None) else ''}. The runs stored before it "
            f"are kept{'; its finished curve is in its checkpoint' if kept else ''}. Free space or fix the "
            f"permissions, then run {_again(spec, store)} again") from None


def _progress(name: str, total: int, quiet: bool):
    from tqdm.auto import tqdm

    in_ci = os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")
    return tqdm(total=total, desc=f"campaign {name}", unit="run", file=sys.stderr,
                disable=quiet or in_ci, dynamic_ncols=True)


# ---- the work of one run (runs in a worker) ----------------------------------
def execute(params, executor: str = "serial", ckpt=None) -> Outcome:
    """Simulate one run; never raises, so one bad run cannot stop the campaign. ``ckpt``:
    (the CampaignStore, seconds) of the run's checkpoint, for the runs that can have one."""
    try:
        from ..checkpoint import CheckpointWarning
        from ..simulate import RunWarning, simulate

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RunWarning)   # the flags are in the summary
            # the provenance holds it, and the campaign process says it (_consume)
            warnings.simplefilter("ignore", CheckpointWarning)
            result = simulate(params, **_checkpoint_args(params, ckpt))
        result.provenance["executor"] = executor    # its threads: tfm.results.provenance, in this worker
        return Outcome(result=result)
    except Exception as exc:
        return Outcome(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())


def _checkpoint_args(params, ckpt) -> dict:
    from ..checkpoint import why_not

    if ckpt is None or why_not(params):
        return {}
    store, every = ckpt
    path = store.checkpoint_path(params.run_id)
    if every is None:
        # no checkpoints: none is saved, but one saved before is still continued from
        # (it was deleted unused, its run computed again from the start)
        if not path.exists():
            return {}
        every = math.inf
    # kept until the campaign process has stored the run (CampaignStore.write_run)
    return {"checkpoint": path, "checkpoint_every": every, "keep_checkpoint": True, "replace_checkpoint": True}


def _set_threads(threads: int, set_env: bool = True) -> None:
    """Numba threads of the calling thread (clamped to the pool numba started with), and,
    for a worker process of our own, NUMBA_NUM_THREADS for scipy.fft."""
    if set_env:
        os.environ["NUMBA_NUM_THREADS"] = str(threads)
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _failure(exc: BaseException) -> Outcome:
    trace = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return Outcome(error=f"{type(exc).__name__}: {exc} (the worker did not return)", traceback=trace)


# ---- executors: each yields (run, outcome) as runs finish --------------------
def _run_serial(todo: list[Run], ckpt=None,
                stop: _Stop | None = None) -> Iterator[tuple[Run, Outcome]]:
    stop = stop or _Stop()
    for run in todo:
        if stop.signum is not None:
            return
        stop.computing = True
        try:
            outcome = execute(run.params, "serial", ckpt)
        finally:
            stop.computing = False
        yield run, outcome


_STARTED = None          # in a pool worker: the queue on which it says what it runs


def _pool_init(threads: int, started=None) -> None:
    global _STARTED
    _STARTED = started
    # Ctrl-C reaches the whole process group: the campaign process decides what stops
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from ..checkpoint import stop_patiently

    stop_patiently()
    signal.signal(signal.SIGTERM, _terminated)
    _die_with_parent()
    _set_threads(threads)


def _terminated(signum, frame) -> None:
    """SIGTERM in a pool worker (the campaign stops its pool, or died): remove the temporary
    snapshot files of the run in progress, then end by SIGTERM as before. They stayed in
    the temporary folder for an hour (4.9 MB each at 1/256). A checkpointed run saves its
    step first (tfm.checkpoint.StopRequest), then passes the signal here."""
    snapshots = sys.modules.get("tfm.snapshots")     # no import in a handler: not loaded, no files
    if snapshots is not None:
        snapshots.remove_live_temporaries()
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGTERM)


def _die_with_parent() -> None:
    """Linux: this worker gets SIGTERM when the campaign process dies (SIGTERM, SIGKILL, a
    crash), instead of computing on as an orphan whose result nobody will store. Its run
    is then simply pending, and the next `tfm campaign run` resumes it."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() == 1:              # the parent died before prctl took effect
        os._exit(1)


def _pool_execute(run_id: str, params, executor: str, ckpt=None) -> Outcome:
    """``execute`` in a pool worker, which first tells the parent which run it took, so
    that a worker killed mid-run (out of memory, SIGKILL) costs that run only."""
    if _STARTED is not None:
        _STARTED.put((os.getpid(), run_id))
    return execute(params, executor, ckpt)


def _death(exitcode) -> str:
    """A worker's exit code in words."""
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        hint = " (the kernel's out-of-memory killer sends SIGKILL)" if name == "SIGKILL" else ""
        return f"was killed by {name}{hint}"
    return f"exited with status {exitcode}"


MAX_UNPINNED = 3            # pool breakages in a row that no run can be blamed for


def _run_pool(todo: list[Run], jobs: int, ckpt=None,
              stop: _Stop | None = None) -> Iterator[tuple[Run, Outcome]]:
    """Runs over a spawned process pool. A worker that dies fails its own run, with the
    cause; the pool is rebuilt and the other runs go on (those in flight are redone).
    On a stop request the runs that finished meanwhile are yielded and the rest dropped."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    stop = stop or _Stop()

    workers = min(jobs, len(todo))
    threads = threads_per_worker(workers)
    # spawn: a fresh interpreter per worker, safe with Numba's threads (fork is not).
    ctx = multiprocessing.get_context("spawn")
    started = ctx.SimpleQueue()
    remaining = {run.run_id: run for run in todo}
    unpinned = 0
    while remaining and stop.signum is None:
        pool, procs, futures = _start_pool(ctx, min(workers, len(remaining)), threads, started,
                                           remaining.values(), ckpt)
        running: dict[int, str] = {}              # worker pid -> the run it said it took
        broken = False
        pending = set(futures)
        try:
            # waits in short slices: a stop request is seen within POLL seconds
            while pending and not broken and stop.signum is None:
                done, pending = wait(pending, timeout=POLL, return_when=FIRST_COMPLETED)
                while not started.empty():        # keep the pipe drained
                    pid, rid = started.get()
                    running[pid] = rid
                for fut in done:
                    run = futures[fut]
                    try:
                        outcome = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        continue
                    except Exception as exc:
                        outcome = _failure(exc)
                    del remaining[run.run_id]
                    yield run, outcome
        finally:
            if pending and not broken:            # stopped, or the caller gave up: do not wait
                _halt(pool)                       # for the runs in flight
            elif not broken:
                pool.shutdown(wait=True, cancel_futures=True)
        if stop.signum is not None:
            for fut in pending:                   # finished while the pool stopped
                if fut.done() and not fut.cancelled() and fut.exception() is None:
                    yield futures[fut], fut.result()
            return
        if not broken:
            return
        pool.shutdown(wait=True, cancel_futures=True)
        while not started.empty():
            pid, rid = started.get()
            running[pid] = rid
        pinned = False
        for pid, proc in procs.items():
            rid = running.get(pid)
            if rid in remaining and proc.exitcode not in (0, -15, None):   # -15: the pool's SIGTERM
                pinned = True
                run = remaining.pop(rid)
                # the pool's SIGTERM made the other workers say they stop: say why, and that
                # their runs go on
                again = "continue from their checkpoints" if ckpt is not None else "start again"
                print(f"tfm: the worker running {rid} (pid {pid}) {_death(proc.exitcode)}; that run "
                      f"fails, the pool is restarted and the runs in flight {again}", file=sys.stderr, flush=True)
                yield run, Outcome(error=f"WorkerDied: the worker process (pid {pid}) running this "
                                         f"run {_death(proc.exitcode)}",
                                   traceback=f"worker pid {pid} {_death(proc.exitcode)} while running "
                                             f"{rid}; the pool was rebuilt and the other runs went on")
        # a death that cannot be pinned on a run (the worker died before it said what it
        # took): rebuild and go on, but not forever
        unpinned = unpinned + 1 if not pinned else 0
        if unpinned >= MAX_UNPINNED:
            break
    if stop.signum is not None:                   # the rest is unfinished, not failed
        return
    for run in list(remaining.values()):
        yield run, Outcome(error=f"WorkerDied: the process pool broke {MAX_UNPINNED} times in a row "
                                 "without a run to blame; not run")


def _halt(pool) -> None:
    """Stop a pool now: its workers are killed (SIGTERM) mid-run, their checkpoints stay,
    and queued runs are dropped."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _start_pool(ctx, workers: int, threads: int, started, runs, ckpt=None):
    """A pool with its workers started; returns (pool, {pid: process}, {future: run})."""
    from concurrent.futures import ProcessPoolExecutor

    # The workers start during the submits below, with NUMBA_NUM_THREADS already set,
    # so Numba starts only `threads` threads in each; the initializer sets it again.
    saved = os.environ.get("NUMBA_NUM_THREADS")
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_pool_init,
                               initargs=(threads, started))
    try:
        label = f"pool[{workers}x{threads}]"
        futures = {pool.submit(_pool_execute, run.run_id, run.params, label, ckpt): run for run in runs}
    finally:
        if saved is None:
            os.environ.pop("NUMBA_NUM_THREADS", None)
        else:
            os.environ["NUMBA_NUM_THREADS"] = saved
    # the worker processes, to read their exit codes if the pool breaks
    procs = dict(getattr(pool, "_processes", None) or {})
    return pool, procs, futures


# The NUMBA_NUM_THREADS a Dask worker was started with (`NUMBA_NUM_THREADS=1 dask worker
# ...` on a shared host), read when a worker first loads this module, before _set_threads
# writes its own: it caps the worker's share of the host's cores (it was overridden).
_OWN_THREADS = os.environ.get("NUMBA_NUM_THREADS", "").strip()


def capped_threads(share: int, own: str = _OWN_THREADS) -> int:
    """``share`` threads, at most the worker's own NUMBA_NUM_THREADS where it set one."""
    return min(share, int(own)) if own.isdigit() and int(own) >= 1 else share


def _execute_dask(params, host_threads: dict[str, int], client_pid: int, height_map=None) -> Outcome:
    """The Dask task: share the host's cores among the worker threads on that host.
    ``height_map``: the run's map (a tfm.surfaces.HeightMap) as the client read it."""
    from distributed import get_worker
    from distributed.comm import get_address_host

    from ..surfaces import HeightMap, given_maps

    worker = get_worker()
    state = getattr(worker, "state", worker)
    host = get_address_host(worker.address)
    threads = capped_threads(threads_per_worker(host_threads.get(host, state.nthreads)))
    # the environment is per process: set it only in a worker process of its own, not
    # in a client that runs its workers in-process (LocalCluster(processes=False))
    _set_threads(threads, set_env=os.getpid() != client_pid)
    maps = {}
    if height_map is not None:
        # hashed again from the heights received; tfm.surfaces.map_heights checks the hash
        # against the run's, as for every run
        maps = {params.height_map: HeightMap(height_map.heights, height_map.pixel_size, height_map.unit)}
    with given_maps(maps):
        outcome = execute(params, f"dask[{threads} thread{'s' if threads != 1 else ''}]")
    res = outcome.result
    if res is not None and res.fields_path is not None:
        # the worker's disk may not be the client's: send the snapshot file back
        path = Path(res.fields_path)
        outcome.fields_bytes = path.read_bytes()
        path.unlink(missing_ok=True)
        res.fields_path = None
    return outcome


def _scatter_maps(client, todo: list[Run]) -> dict:
    """The height maps of ``todo``, read here once each and sent to the cluster, whose
    workers need not see this machine's files: path -> a future of its HeightMap."""
    from ..surfaces import MapError, load_height_map

    maps = {}
    for path in dict.fromkeys(r.params.height_map for r in todo if r.params.shape == "height_map"):
        try:
            maps[path] = client.scatter(load_height_map(path), hash=False)
        except MapError as exc:
            raise CampaignError(str(exc)) from None
    return maps


def _dask_client(scheduler):
    """A client of the cluster at ``scheduler`` (an address), or ``scheduler`` itself if it
    is a client already."""
    try:
        from distributed import Client
    except ImportError:
        raise CampaignError("--scheduler needs dask.distributed: pip install 'tfm[dask]'") from None
    if hasattr(scheduler, "submit"):
        return scheduler
    try:
        return Client(scheduler, timeout="30s")
    except (OSError, TimeoutError, ValueError) as exc:     # ValueError: an address without a port, say
        raise CampaignError(f"scheduler: cannot reach the Dask scheduler at {scheduler} ({exc}); is it "
                            "running, and is the address right (e.g. tcp://host:8786)?") from None


def _run_dask(todo: list[Run], client,
              stop: _Stop | None = None) -> Iterator[tuple[Run, Outcome]]:
    from distributed import as_completed as dask_completed
    from distributed.comm import get_address_host
    from tqdm.auto import tqdm

    host_threads: dict[str, int] = {}
    for addr, info in client.scheduler_info().get("workers", {}).items():
        host = info.get("host") or get_address_host(addr)
        host_threads[host] = host_threads.get(host, 0) + int(info.get("nthreads", 1))
    maps = _scatter_maps(client, todo)
    futures = {client.submit(_execute_dask, run.params, host_threads, os.getpid(),
                             maps.get(run.params.height_map), pure=False): run
               for run in todo}
    stop = stop or _Stop()
    seen = set()
    alone_since, said = None, False
    try:
        finished = dask_completed(list(futures))
        while not finished.is_empty() and stop.signum is None:
            batch = finished.next_batch(block=False)
            if not batch:
                time.sleep(POLL)          # short naps: a stop request is seen at once
                # every worker gone: the tasks wait for one, and the campaign waited in silence
                if not said and not client.scheduler_info().get("workers"):
                    alone_since = alone_since or time.monotonic()
                    if time.monotonic() - alone_since >= NO_WORKERS_NOTE:
                        said = True
                        # tqdm.write: on a line of its own, above the progress bar
                        tqdm.write(f"tfm: no Dask worker has been connected to {client.scheduler.address} for "
                                   f"{NO_WORKERS_NOTE:g} s; the campaign waits for one (Ctrl-C stops it; the "
                                   "runs stored so far stay)", file=sys.stderr)
                else:
                    alone_since = None
            for fut in batch:
                try:
                    outcome = fut.result()
                except Exception as exc:      # the worker died or the task was lost
                    outcome = _failure(exc)
                seen.add(fut)
                yield futures[fut], outcome
    finally:
        client.cancel([f for f in futures if not f.done()])
    if stop.signum is not None:           # finished while the campaign stopped
        for fut in futures:
            if fut not in seen and fut.status == "finished":
                yield futures[fut], fut.result()
