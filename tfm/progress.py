"""Progress of a single run: a bar over the dilatation steps, and a note when the compiled
kernels are not cached yet (the first run after an install or a code change compiles them).

The bar is off with ``quiet``, when ``CI=true``, and when stderr is not a terminal.
"""
from __future__ import annotations

import contextlib
import os
import sys
import time

# Kernels every run calls: if one of these has no valid on-disk cache entry, the run
# starts by compiling. Dispatchers defined in tfm.solver count too (the compiled step).
HOT_KERNELS = (("tfm.kernels.grid", "blocked_dot"),)
SOLVER_MODULE = "tfm.solver"


BATCH_EVERY = 60.0      # seconds between progress lines when stderr is not a terminal


def say(text: str) -> None:
    """A line on stderr when a run is stopped. Its reader may be gone: Ctrl-C also ends the
    `tee` that a run's output is piped through, and the BrokenPipeError of a plain print
    stopped the run before it saved its state. Then stderr goes to /dev/null from here on."""
    try:
        print(text, file=sys.stderr, flush=True)
    except BrokenPipeError:
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stderr.fileno())
        except (OSError, ValueError):   # no file descriptor (a replaced sys.stderr)
            pass


def counted(n: int, noun: str) -> str:
    """'1 run', '2 runs', '0 runs' (the plural by an s)."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def _dispatchers():
    import importlib

    from numba.core.registry import CPUDispatcher

    for module, name in HOT_KERNELS:
        yield getattr(importlib.import_module(module), name)
    for value in vars(importlib.import_module(SOLVER_MODULE)).values():
        if isinstance(value, CPUDispatcher):
            yield value


# compiled only for force control (tfm.solver.ContactState.unit_response; displacement control
# prepares its predictions inside snap_rounds: prepare_predictions)
FORCE_CONTROL_ONLY = ("solve_on_set",)


def cold_kernels(control: str = "displacement", data: str | None = None) -> list[str]:
    """Names of the hot kernels a run under ``control`` uses whose Numba cache is missing
    or stale (they will compile). ``data``: the class of the operator's compiled data
    (``tfm.operators.compiled_data_name``); a kernel specialised on operator data is cold
    too when its cache holds only other operators' (a first direct run after FFT runs
    compiled for 20 s without a word).

    Reads each dispatcher's cache index, which Numba empties when the source changed.
    Returns [] if the check itself is not possible (another Numba version)."""
    from .operators import DATA_CLASSES

    names = [cls.__name__ for cls in DATA_CLASSES]
    cold = []
    try:
        for disp in {id(d): d for d in _dispatchers()}.values():
            if control != "force" and disp.py_func.__name__ in FORCE_CONTROL_ONLY:
                continue       # never compiled by such a run: "compiling" would show on every run
            cache = getattr(disp, "_cache", None)
            index = cache._cache_file._load_index() if hasattr(cache, "_cache_file") else {}
            sigs = [str(key[0]) for key in index]
            by_data = [s for s in sigs if any(f"{name}(" in s for name in names)]
            if not sigs or (data is not None and by_data and not any(f"{data}(" in s for s in by_data)):
                cold.append(disp.py_func.__qualname__)
    except (AttributeError, ImportError, OSError, TypeError, IndexError):
        return []
    return cold


@contextlib.contextmanager
def run_progress(p, quiet: bool = False, stream=None):
    """A ``progress(record)`` callback for ``tfm.simulate`` that drives a tqdm bar."""
    stream = stream or sys.stderr
    if quiet:
        yield None
        return
    from .operators import compiled_data_name

    cold = cold_kernels(p.control, compiled_data_name(p))
    if cold:
        print(f"compiling Numba kernels ({', '.join(cold)}; first run after an install or a code change, "
              "cached for later runs) ...", file=stream, flush=True)
    from tqdm.auto import tqdm

    from .protocol import n_loading_steps

    show = not in_ci() and (stream.isatty() if hasattr(stream, "isatty") else False)
    bar = tqdm(total=None, desc=f"tfm run {p.run_id[:8]}", unit="step", file=stream,
               disable=not show, dynamic_ncols=True, mininterval=0.2)
    n_load = n_loading_steps(p)
    # a batch job's log (nohup, sbatch, a file): no bar, but a line every BATCH_EVERY seconds;
    # a 15-minute run at 1/2048 printed nothing between its header and its end
    batch = not show and not in_ci()
    start = last = time.monotonic()

    def progress(rec) -> None:
        nonlocal last
        where = (f"{rec.phase}{'' if rec.phase != 'load' else f' {rec.step + 1}/{n_load}'} "
                 f"d={rec.d:+.4g} contact={rec.n_contact}")
        bar.update(1)
        bar.set_postfix_str(where, refresh=False)
        if batch and time.monotonic() - last >= BATCH_EVERY:
            last = time.monotonic()
            print(f"tfm run {p.run_id[:8]}: step {rec.step + 1}, {where}, {(last - start) / 60:.1f} min",
                  file=stream, flush=True)

    try:
        yield progress
    finally:
        bar.close()
