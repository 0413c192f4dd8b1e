"""`tfm campaign run|status|list|expand`: the command line of campaigns."""
from __future__ import annotations

import json
import shutil
import signal
import sys
from pathlib import Path

from ..progress import counted, say
from .spec import CampaignError, load_spec

RESULTS_DIR = "results"      # default parent of results/<name>/


def register(subparsers) -> None:
    camp = subparsers.add_parser(
        "campaign", help="grids of runs from a TOML file (run, status, list, expand)",
        description="Campaigns: a TOML file in campaigns/ sweeps parameters; the runs go to "
                    "results/<name>/ as summary.parquet, curves.parquet and failures.parquet.")
    sub = camp.add_subparsers(dest="campaign_command", required=True)

    run = sub.add_parser("run", help="run the runs not yet stored (resumes after a crash)",
                         description="Run a campaign. Finished runs are skipped, failed and "
                                     "unfinished ones are (re)done. Exit status 1 if a run failed, or "
                                     "if a computed run or the tables could not be stored; 2: bad input.")
    run.add_argument("file", help="campaign file, e.g. campaigns/smoke.toml")
    run.add_argument("-j", "--jobs", type=int, default=1,
                     help="local worker processes; the cores are divided among them (default 1)")
    run.add_argument("--scheduler", metavar="ADDR", default=None,
                     help="run on a Dask distributed cluster, e.g. tcp://host:8786")
    run.add_argument("-q", "--quiet", action="store_true",
                     help="no progress bar, no line per failed run and no closing line (the bar is also off "
                          "when CI=true); warnings, the count of failed runs and the lines of a stop "
                          "signal stay")
    run.add_argument("--results-dir", default=RESULTS_DIR, help="parent of results/<name>/ (default results)")
    run.add_argument("--skip-failed", action="store_true",
                     help="do not retry runs that failed before")
    run.add_argument("--rerun-stale", action="store_true",
                     help="recompute runs stored by other tfm source code (their prov_code_hash, a hash of "
                          "the files of tfm/, differs from this code's)")
    run.add_argument("--where", action="append", default=[], metavar="KEY=VALUE",
                     help="compute only the runs with this parameter value, e.g. self_term=3.8 or "
                          "spacing=1/1340 (repeat to combine); the rest stay pending")
    checkpoint_flag(run)
    _max_runs_flag(run)
    run.set_defaults(func=cmd_run)

    status = sub.add_parser("status", help="how many runs are done, pending and failed "
                                           "(exit status 1 if any failed)",
                            description="How many runs of a campaign are done (and flagged), pending and "
                                        "failed, and what else is found in its folder. Exit status 1 if a "
                                        "run failed; 2: bad input.")
    status.add_argument("file", help="campaign file, e.g. campaigns/smoke.toml")
    _max_runs_flag(status)
    status.add_argument("--results-dir", default=RESULTS_DIR,
                        help="parent of results/<name>/ (default results; another one must exist)")
    status.add_argument("-v", "--verbose", action="store_true", help="one line per run")
    status.set_defaults(func=cmd_status)

    lst = sub.add_parser("list", help="the campaign files and their progress",
                         description="One line per campaign file: its runs, how many are done and failed, "
                                     "and its description. Exit status 2 if a file is invalid.")
    lst.add_argument("--dir", default="campaigns", help="folder of campaign files (default campaigns)")
    lst.add_argument("--results-dir", default=RESULTS_DIR,
                     help="parent of results/<name>/ (default results; another one must exist)")
    lst.set_defaults(func=cmd_list)

    expand = sub.add_parser("expand", help="print the runs a campaign file expands to",
                            description="Print the runs a campaign file expands to, in order: index, run id "
                                        "and the swept values (--json: every parameter). Nothing is run.")
    expand.add_argument("file", help="campaign file, e.g. campaigns/smoke.toml")
    _max_runs_flag(expand)
    expand.add_argument("--json", action="store_true", help="one JSON object per run, all parameters")
    expand.set_defaults(func=cmd_expand)


def checkpoint_flag(parser) -> None:
    from ..config import CHECKPOINT_EVERY

    # one or the other: given both, the last one won without a word
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--checkpoint-every", type=float, default=CHECKPOINT_EVERY, metavar="SECONDS",
                       help="save a running curve's state this often, in <results>/<name>/checkpoints/, "
                            f"so that a killed run continues from there (default {CHECKPOINT_EVERY:g}; 0 "
                            "saves after every step, which can make a run 20x slower; --no-checkpoints "
                            "turns them off)")
    group.add_argument("--no-checkpoints", dest="checkpoint_every", action="store_const", const=None,
                       help="save no checkpoints (a killed run starts again from its first step; "
                            "one saved earlier is still continued from)")


def _max_runs_flag(parser) -> None:
    parser.add_argument("--max-runs", type=int, default=None, metavar="N",
                        help="confirm a campaign of more than 10,000 runs (as max_runs = N in the file)")


def cmd_run(args) -> int:
    from .runner import run_campaign
    from .store import CampaignStore

    from .spec import select_runs

    spec = load_spec(args.file, max_runs=args.max_runs)
    only = {r.run_id for r in select_runs(spec, args.where)} if args.where else None
    parent = Path(args.results_dir).expanduser().absolute().parent
    if not parent.exists():
        # a mistyped path started the campaign afresh in a whole new tree of folders
        raise CampaignError(f"results-dir: {parent}, the folder that would hold {args.results_dir}, does not "
                            "exist (a results folder is made inside an existing one)")
    try:
        root = run_campaign(spec, jobs=args.jobs, scheduler=args.scheduler, quiet=args.quiet,
                            results_dir=args.results_dir, retry_failed=not args.skip_failed,
                            rerun_stale=args.rerun_stale, only=only,
                            checkpoint_every=args.checkpoint_every)
    except KeyboardInterrupt as exc:      # CampaignInterrupted: the message says how to resume
        say(f"tfm: {str(exc) or 'interrupted'}")
        return 128 + getattr(exc, "signum", signal.SIGINT)
    status = CampaignStore(root).status(spec)
    if status.flagged:                    # even with --quiet: a warning
        print(f"{len(status.flagged)} runs are flagged (see the r_warnings column of "
              f"{root / 'summary.parquet'})", file=sys.stderr)
    if status.failed:
        print(f"{counted(len(status.failed), 'run')} failed; tracebacks in {root / 'failures.parquet'}",
              file=sys.stderr)
        return 1
    return 0


def cmd_status(args) -> int:
    from .store import CampaignStore

    spec = load_spec(args.file, max_runs=args.max_runs)
    _check_results_dir(args.results_dir)
    store = CampaignStore.for_spec(spec, args.results_dir)
    conflict = store.source_conflict(spec)
    if conflict:
        print(f"tfm: error: {conflict}", file=sys.stderr)
        return 2
    st = store.status(spec)
    print(f"{spec.name}: {st.total} runs: {len(st.done)} done ({len(st.flagged)} flagged), "
          f"{len(st.pending)} pending, {len(st.failed)} failed"
          + (f", {len(st.stale)} computed by other tfm code (--rerun-stale)" if st.stale else "")
          + f"  [{store.root}]")
    if not store.root.is_dir():
        print(f"  nothing stored yet: {store.root} does not exist (not run with this --results-dir)")
    from ..paper import kept_limit_points
    points, kept = kept_limit_points(spec.name)
    kept &= set(st.pending)
    if kept:
        # the limit study keeps a point per run, not the run: this campaign would compute them again
        print(f"  {len(kept)} pending runs have a kept point in {points}: `tfm limit` (make limit) fits those "
              "and computes only the rest; `tfm campaign run` would compute them again")
    for note in (store.damaged_note(st), store.extra_note(st)):
        if note:
            print(f"  {note}")
    holder = store.running()
    if holder:
        print(f"  {holder} is running this campaign now: the tables are rebuilt when it finishes")
    elif (st.done or st.failed or store.table_path("summary").exists()) and (behind := store.tables_behind(spec, st)):
        # with every run pending after an edit, the tables on disk still held the old rows
        print(f"  the tables (summary, curves, failures) are out of date: {behind}; "
              f"`{store.run_command(args.file)}` rebuilds them")
    saved = _checkpoints(store, st.pending + st.failed)
    if saved:
        usable = sum(ok for ok, _ in saved.values())
        said = []
        if usable:
            said.append(f"{usable} unfinished run{'s have a checkpoint: they continue' if usable > 1 else ' has a checkpoint: it continues'} from it")
        if len(saved) - usable:
            n = len(saved) - usable
            said.append(f"{n} unfinished run{'s have a checkpoint' if n > 1 else ' has a checkpoint'} that "
                        f"cannot be continued from (see below): {'they start' if n > 1 else 'it starts'} afresh")
        print("  " + "; ".join(said))
    orphans = store.orphan_checkpoints(spec)
    if orphans:
        print(f"  {counted(len(orphans), 'checkpoint')} in {store.checkpoints_dir} belong{'s' if len(orphans) == 1 else ''} to runs no longer in the file "
              f"({', '.join(orphans[:3])}{', ...' if len(orphans) > 3 else ''}): they are kept; put the "
              "values back to continue them, or delete them")
    state = {**{r: "pending" for r in st.pending}, **{r: "done" for r in st.done},
             **{r: "flagged" for r in st.flagged}, **{r: "failed" for r in st.failed}}
    for run in spec.runs:
        rid = run.run_id
        if args.verbose or state[rid] == "failed":
            line = f"  {run.index:4d} {rid} {state[rid]:8s} {_swept(run)}"
            if state[rid] == "failed":
                line += f"  {(store.read_failure(rid) or {}).get('error', '')}"
            if rid in saved:
                line += f"  [{saved[rid][1]}]"
            print(line)
    return 1 if st.failed else 0


def _check_results_dir(results_dir: str) -> None:
    """A results folder to read must exist (a mistyped one showed every run as pending);
    the default one may not exist yet."""
    if results_dir != RESULTS_DIR and not Path(results_dir).expanduser().is_dir():
        raise CampaignError(f"results-dir: {results_dir} is not a folder")


def _checkpoints(store, run_ids) -> dict[str, tuple[bool, str]]:
    """run id -> (whether the run continues from it, what its checkpoint holds), for the
    runs in ``run_ids`` that have one."""
    if not store.checkpoints_dir.is_dir():
        return {}
    from ..checkpoint import read_meta, unusable

    saved = {}
    for rid in run_ids:
        path = store.checkpoint_path(rid)
        if path.exists():
            meta = read_meta(path)
            why = "cannot be read (damaged?)" if meta is None else unusable(meta, rid)
            if why:
                saved[rid] = (False, f"checkpoint {path} {why}: the run will start afresh")
                continue
            elapsed = float(meta.get("elapsed", float("nan")))
            spent = f"{elapsed:.0f} s" if elapsed < 60 else f"{elapsed / 60:.1f} min"
            saved[rid] = (True, f"checkpoint: {meta.get('steps', '?')} steps, {spent}, "
                                f"written {meta.get('written_at', '?')}")
    return saved


def cmd_list(args) -> int:
    from .store import CampaignStore

    if not Path(args.dir).is_dir():
        raise CampaignError(f"dir: {args.dir} is not a folder")
    _check_results_dir(args.results_dir)
    files = sorted(Path(args.dir).glob("*.toml"))
    if not files:
        print(f"no campaign files in {args.dir}/", file=sys.stderr)
    # one line per file: the names in one column, the description on one line, cut to a
    # terminal's width (the whole of it is in the file, and in a pipe)
    width = max((len(path.stem) for path in files), default=0)
    columns = shutil.get_terminal_size().columns if sys.stdout.isatty() else None
    invalid = 0
    for path in files:
        try:
            spec = load_spec(path)
        except CampaignError as exc:
            print(f"{path.stem:{width}s} INVALID: {exc}")
            invalid += 1
            continue
        store = CampaignStore.for_spec(spec, args.results_dir)
        if store.source_conflict(spec):
            # its name's folder holds another file's results: their counts are not its own
            progress = f"{len(spec.runs):4d} runs (its folder {store.root} holds another campaign file's results)"
        else:
            st = store.status(spec)
            progress = f"{st.total:4d} runs {len(st.done):4d} done {len(st.failed):3d} failed"
        # the results folder follows the name inside the file, which may differ from the file's
        named = f"(name {spec.name!r}, results in {store.root}) " if spec.name != path.stem else ""
        line = f"{path.stem:{width}s} {progress}  {named}" + " ".join(spec.description.split())
        print(line if columns is None or len(line) <= columns else line[:columns - 3] + "...")
    return 2 if invalid else 0            # a script sees an invalid file (exit 0 hid it)


def cmd_expand(args) -> int:
    spec = load_spec(args.file, max_runs=args.max_runs)
    for run in spec.runs:
        if args.json:
            print(json.dumps({"index": run.index, "run_id": run.run_id, **run.params.to_dict()}))
        else:
            print(f"{run.index:4d} {run.run_id} {_swept(run)}")
    return 0


def _swept(run) -> str:
    return " ".join(f"{k}={v}" for k, v in run.swept.items())
