"""`tfm run`'s figure, drawn by a second process while the first computes the curve.

Matplotlib and a figure's first drawing (fonts, the math-text parser) take about as
long as a 1/128 curve, and such a curve runs on one core. So `tfm run` starts this worker
before the run. The worker imports and draws a throwaway figure meanwhile, then waits for
one line on stdin: the curve's columns and a temporary path for the figure, sent as soon
as the curve is computed. It draws the figure there exactly as `tfm plot` would from the
table (the same columns, the run's parameter record), while `tfm run` writes the table,
then answers ``done`` on stdout, and `tfm run` moves the figure into place once the table
is written. Without that line (the run failed or was interrupted) it exits without
drawing. On any other answer (a failure is reported on stderr) `tfm run` draws the figure
itself.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

# seconds `tfm run` waits for the figure once the table is written (then it draws it itself)
WAIT = 120.0
DONE = "done"
# Larger grids get no worker: their curves take 15 s and more, against which the 0.3-0.5 s
# saved do not count, and the idle worker would hold its 150 MiB (Matplotlib
# loaded) through the whole run. 65536 springs: a 1/256 standard curve has 159^2, 1/512 307^2.
MAX_SPRINGS = 65536


def start_worker(p) -> PlotWorker | None:
    """A worker for the run ``p``'s figure, or None (a large grid, or no process to be had:
    `tfm run` then draws the figure itself)."""
    from .guards import n_springs

    if n_springs(p) > MAX_SPRINGS:
        return None
    try:
        return PlotWorker(p.canonical_json())
    except OSError:
        return None


class PlotWorker:
    """The worker process, seen from `tfm run`."""

    command = (sys.executable, "-m", "tfm.plot_worker")

    def __init__(self, params_json: str):
        self.proc = subprocess.Popen((*self.command, params_json), stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.plot = self.tmp = self._writer = None
        self.failed = None

    def send(self, res, plot: Path) -> None:
        """Have the curve of ``res`` (a RunResult) drawn for ``plot``: into a temporary file
        beside it, which ``finish`` moves into place. The line is written by a thread: a
        curve of some 500 steps and more is longer than the pipe's buffer, and a worker
        that does not read (stopped, or still warming up) must not hold up the table."""
        self.plot = Path(plot)
        self.tmp = self.plot.with_name(f".{self.plot.stem}.{os.getpid()}.worker{self.plot.suffix}")
        line = json.dumps({"columns": {c: v.tolist() for c, v in res.columns().items()},
                           "plot": str(self.tmp)}) + "\n"
        self._writer = threading.Thread(target=self._write, args=(line,), daemon=True)
        self._writer.start()

    def _write(self, line: str) -> None:
        try:
            self.proc.stdin.write(line)
            self.proc.stdin.flush()
        except (OSError, ValueError) as exc:   # it died, or was ended, before reading it all
            self.failed = self.failed or str(exc)

    def finish(self) -> str | None:
        """Wait, at most WAIT seconds, for the figure sent and move it into place: None
        once it is there, else why not (nothing of it is left then)."""
        deadline = time.monotonic() + WAIT
        self._writer.join(WAIT)
        if self._writer.is_alive():
            self.failed = f"no answer after {WAIT:g} s"
        if self.failed is None:
            try:
                out, err = self.proc.communicate(timeout=max(deadline - time.monotonic(), 0.0))
            except subprocess.TimeoutExpired:
                out, err = "", f"no answer after {WAIT:g} s"
            except OSError as exc:
                out, err = "", str(exc)
            if out.strip() == DONE and self.proc.returncode == 0:
                os.replace(self.tmp, self.plot)
                self.tmp = None
                return None
            lines = (err or "").strip().splitlines()
            self.failed = lines[-1] if lines else f"exit status {self.proc.returncode}"
        self.cancel()
        return self.failed

    def cancel(self) -> None:
        """No figure from the worker (the run failed or was interrupted, or the worker
        did): end it now, and remove anything it drew. A failed run must not wait for its
        warm-up."""
        if self.proc.returncode is None:
            self.proc.kill()
            self.proc.wait()
        if self._writer is not None:
            self._writer.join(5.0)         # a write to the dead process fails at once
        for pipe in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            try:
                pipe.close()
            except (OSError, ValueError):
                pass
        if self.tmp is not None:
            self.tmp.unlink(missing_ok=True)


def _warm(params_json: str):
    """Import what the figure needs and save a throwaway one with the run's caption, style
    and dpi, so that fonts, the math-text parser and the layout code are loaded when the
    real curve arrives (its draw then took 0.21-0.23 s at 1/128 instead of 0.52 s).
    Returns that figure: drawn again, its renderer has measured the caption, the labels
    and, from loads of the run's size, most tick labels (the draw then took 0.15-0.19 s,
    same bytes; 2026-11-24)."""
    import tempfile

    import numpy as np

    from . import theory
    from .params import Params
    from .plots import plot_curve
    from .units import force_scale

    try:
        p = Params.from_dict(json.loads(params_json))
    except Exception:                    # the real figure will say what is wrong
        p = None
    indent = np.r_[np.linspace(0.0, 1.0, 8), np.linspace(1.0, -0.1, 8)] * (p.delta_max if p else 0.05)
    curve = {"phase": np.array(["load"] * 8 + ["unload"] * 8), "indent": indent, "force": indent,
             "contact_radius": np.abs(indent), "n_contact": np.ones(indent.size, dtype=np.int64)}
    if p is not None and p.shape != "height_map":
        # loads of the size the run's will have (its reference curve, and a pull-off of
        # the same order): the real figure's tick labels are then mostly measured already
        top = float(theory.preload_force(p.shape, p.delta_max, p.radius)) * force_scale(p)
        curve["force"] = np.r_[np.linspace(0.0, top, 8), np.linspace(top, -0.7 * top, 8)]
        curve["contact_radius"] = np.sqrt(np.abs(indent) * p.radius)
    with tempfile.TemporaryDirectory() as tmp:
        fig = plot_curve(curve, p, Path(tmp) / "warm.png")
    return fig


def main(params_json: str) -> int:
    fig = _warm(params_json)
    line = sys.stdin.readline()
    if not line.strip():
        return 0
    job = json.loads(line)
    from .params import Params
    from .plots import plot_curve

    params = Params.from_dict(json.loads(params_json))
    # the figure `tfm plot` would draw from the table: the same columns and record (as
    # NumPy arrays: pandas is not imported here, tfm.plots.curve_arrays)
    plot_curve(job["columns"], params, Path(job["plot"]), reuse=fig)
    return 0


if __name__ == "__main__":
    import gc
    gc.disable()                             # a short life, no garbage cycles to speak of (tfm.cli.main)
    try:
        status = main(sys.argv[1] if len(sys.argv) > 1 else "{}")
    except Exception as exc:                  # reported to tfm run, which draws the figure itself
        print(f"{type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
    if status == 0:
        print(DONE, flush=True)
    sys.stderr.flush()
    # the figure is written and renamed: skip the interpreter's teardown of Matplotlib
    # (0.2 s), which tfm run would otherwise wait for
    os._exit(status)
