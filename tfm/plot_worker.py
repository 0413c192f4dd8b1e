"""`tfm run`'s figure, drawn by a second process while the first computes the curve.

Matplotlib, pandas and a figure's first drawing (fonts, the math-text parser) take about as
long as a 1/128 curve, and such a curve runs on one core. So `tfm run` starts this worker
before the run. The worker imports and draws a throwaway figure meanwhile, then waits for
one line on stdin, ``{"table": ..., "plot": ...}``, and draws the figure from the written
table exactly as `tfm plot` does (the table holds the curve and the parameter record).
Without that line (the run failed or was interrupted) it exits without drawing. It answers
``done`` on stdout once the figure is in place; anything else (a failure is reported on
stderr) and `tfm run` draws the figure itself.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

# seconds `tfm run` waits for the figure once the table is written (then it draws it itself)
WAIT = 120.0
DONE = "done"
# Larger grids get no worker: their curves take 15 s and more, against which the 0.3-0.5 s
# saved do not count, and the idle worker would hold its 150 MiB (Matplotlib and pandas
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

    def _finish(self, line: str) -> tuple[str, str]:
        try:
            return self.proc.communicate(line, timeout=WAIT)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            return "", f"no answer after {WAIT:g} s"

    def draw(self, table: Path, plot: Path) -> str | None:
        """Have the figure of ``table`` written to ``plot``: None once it is there, else
        why not."""
        try:
            out, err = self._finish(json.dumps({"table": str(table), "plot": str(plot)}) + "\n")
        except OSError as exc:                 # it died before reading its line
            self.proc.kill()
            self.proc.communicate()
            return str(exc)
        if out.strip() == DONE and self.proc.returncode == 0:
            return None
        lines = (err or "").strip().splitlines()
        return lines[-1] if lines else f"exit status {self.proc.returncode}"

    def cancel(self) -> None:
        """No figure (the run failed or was interrupted): end the worker now. It has
        written nothing, and a failed run must not wait for its warm-up."""
        self.proc.kill()
        self.proc.communicate()


def _warm(params_json: str):
    """Import what the figure needs and save a throwaway one with the run's caption, style
    and dpi, so that fonts, the math-text parser and the layout code are loaded when the
    real curve arrives (its draw then took 0.21-0.23 s at 1/128 instead of 0.52 s).
    Returns that figure: drawn again, its renderer has measured the caption, the labels
    and, from loads of the run's size, most tick labels (the draw then took 0.15-0.19 s,
    same bytes; 2026-11-24)."""
    import tempfile

    import numpy as np
    import pandas as pd

    from . import theory
    from .params import Params
    from .plots import plot_curve
    from .units import force_scale
    from .results import CURVE_COLUMNS

    try:
        p = Params.from_dict(json.loads(params_json))
    except Exception:                    # the real figure will say what is wrong
        p = None
    indent = np.r_[np.linspace(0.0, 1.0, 8), np.linspace(1.0, -0.1, 8)] * (p.delta_max if p else 0.05)
    curve = pd.DataFrame({c: np.zeros(indent.size) for c in CURVE_COLUMNS})
    curve["phase"] = ["load"] * 8 + ["unload"] * 8
    curve["indent"], curve["d"], curve["force"] = indent, -indent, indent
    curve["contact_radius"], curve["n_contact"] = np.abs(indent), 1
    if p is not None and p.shape != "height_map":
        # loads of the size the run's will have (its reference curve, and a pull-off of
        # the same order): the real figure's tick labels are then mostly measured already
        top = float(theory.preload_force(p.shape, p.delta_max, p.radius)) * force_scale(p)
        curve["force"] = np.r_[np.linspace(0.0, top, 8), np.linspace(top, -0.7 * top, 8)]
        curve["contact_radius"] = np.sqrt(np.abs(indent) * p.radius)
    with tempfile.TemporaryDirectory() as tmp:
        fig = plot_curve(curve, p, Path(tmp) / "warm.png")
    import pyarrow.parquet  # noqa: F401  (the table is read with it)
    return fig


def main(params_json: str) -> int:
    fig = _warm(params_json)
    line = sys.stdin.readline()
    if not line.strip():
        return 0
    job = json.loads(line)
    from .plots import write_curve_figure
    from .viewcli import load_run

    table = Path(job["table"])
    curve, params, _ = load_run(table)
    if params is None:               # tfm run would draw it with the caption: let it
        raise ValueError(f"{table}: the parameter record did not rebuild")
    write_curve_figure(curve, params, Path(job["plot"]), reuse=fig)
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
    # the figure is written and renamed: skip the interpreter's teardown of Matplotlib and
    # pandas (0.2 s), which tfm run would otherwise wait for
    os._exit(status)
