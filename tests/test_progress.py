"""`tfm run` progress: a bar over the dilatation steps in a terminal, none with -q or CI=true."""
import fcntl
import io
import os
import pty
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from tfm.progress import cold_kernels

ROOT = Path(__file__).resolve().parents[1]
RUN_128 = ["run", "--spacing", "1/128", "--alpha", "0.75", "--k-th", "0.02", "--shape", "paraboloid",
           "--max-indent", "0.05", "--no-plot"]


def _run_in_terminal(args, tmp_path, env_extra=None):
    """Run `python -m tfm.cli ARGS` with stdout and stderr on a pseudo-terminal; return the text."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_NUM_THREADS": "1", "COLUMNS": "120"}
    env.pop("CI", None)
    env.update(env_extra or {})
    master, slave = pty.openpty()
    # a terminal 120 columns wide (a fresh pseudo-terminal reports 0 x 0)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    proc = subprocess.Popen([sys.executable, "-m", "tfm.cli", *args, "-o", str(tmp_path / "c.parquet")],
                            stdout=slave, stderr=slave, stdin=subprocess.DEVNULL, env=env, cwd=tmp_path)
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], 1.0)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:          # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    proc.wait(timeout=300)
    os.close(master)
    return proc.returncode, b"".join(chunks).decode(errors="replace")


def test_a_1_128_run_shows_a_bar_in_a_terminal(tmp_path):
    rc, text = _run_in_terminal(RUN_128, tmp_path)
    assert rc == 0, text
    assert "step/s" in text or "s/step" in text          # tqdm's rate
    assert "unload" in text and "contact=" in text and "d=" in text


def test_no_bar_with_quiet(tmp_path):
    small = ["run", "--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.02",
             "--step", "1e-3", "--no-plot", "-q"]
    rc, text = _run_in_terminal(small, tmp_path)
    assert rc == 0, text
    assert "step/s" not in text and "s/step" not in text and "tfm run" not in text


class _Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize("ci, shown", [("true", False), ("", True)])
def test_no_bar_when_ci_is_true(monkeypatch, ci, shown):
    from tfm import Params
    from tfm.progress import run_progress
    from tfm.solver import StepRecord

    monkeypatch.setenv("CI", ci)
    stream = _Terminal()
    with run_progress(Params(spacing=1 / 16, k_th=0.02, f_th=None, shape="paraboloid"), stream=stream) as cb:
        for k in range(3):
            cb(StepRecord(k, "load", -1e-3 * k, 0.0, 0.0, 1, 0, 0, 1, 1))
    assert ("step/s" in stream.getvalue() or "s/step" in stream.getvalue()) is shown


@pytest.mark.parametrize("ci, lines", [("", 3), ("true", 0)])
def test_a_batch_log_gets_a_progress_line_now_and_then(monkeypatch, ci, lines):
    """With stderr a file (nohup, sbatch) the bar is off, and a 15-minute run printed
    nothing between its header and its end. Now a plain line every BATCH_EVERY seconds."""
    import tfm.progress
    from tfm import Params
    from tfm.progress import run_progress
    from tfm.solver import StepRecord

    monkeypatch.setenv("CI", ci)
    monkeypatch.setattr(tfm.progress, "BATCH_EVERY", 0.0)
    stream = io.StringIO()                                     # not a terminal
    p = Params(spacing=1 / 16, k_th=0.02, f_th=None, shape="paraboloid")
    with run_progress(p, stream=stream) as cb:
        for k in range(3):
            cb(StepRecord(k, "load", -1e-3 * k, 0.0, 0.0, 1, 0, 0, 1, 1))
    got = [line for line in stream.getvalue().splitlines() if line.startswith(f"tfm run {p.run_id[:8]}: step")]
    assert len(got) == lines
    if lines:
        assert got[-1].startswith(f"tfm run {p.run_id[:8]}: step 3, load 3/") and "d=-0.002 contact=1" in got[-1]


def test_cold_cache_detection_names_kernels(monkeypatch):
    import tfm.kernels.grid as grid

    assert isinstance(cold_kernels(), list)
    # a cache index that does not match the source (as after an edit) means compiling
    monkeypatch.setattr(grid.blocked_dot._cache._cache_file, "_load_index", lambda: {})
    assert "blocked_dot" in cold_kernels()


def test_a_kernel_only_force_control_compiles_is_not_announced_for_other_runs(monkeypatch):
    """solve_on_set compiles only under force control, so its cache stays empty after any
    number of displacement-controlled runs, and each of them said "compiling" (a new
    user's finding)."""
    import tfm.solver as solver

    monkeypatch.setattr(solver.solve_on_set._cache._cache_file, "_load_index", lambda: {})
    assert "solve_on_set" not in cold_kernels("displacement")
    assert "solve_on_set" in cold_kernels("force")


def test_a_first_run_of_another_operator_is_announced(monkeypatch):
    """The compiled loop is specialised on the operator's data: after FFT runs, the first
    direct run compiled for 20 s and the first tree run for 44 s without the "compiling"
    note, since the cache index was not empty (a user's hunt)."""
    import tfm.kernels.contact as contact
    from tfm.operators import compiled_data_name
    from tfm.params import Params

    fft_only = {("(FFTData(int64, float64), PreData(int64))", "target"): 1}
    monkeypatch.setattr(contact.snap_rounds._cache._cache_file, "_load_index", lambda: fft_only)
    assert "snap_rounds" not in cold_kernels(data="FFTData")
    assert "snap_rounds" in cold_kernels(data="DirectData")
    assert [compiled_data_name(Params(operator=op, kernel=k)) for op, k in
            (("fft", "boussinesq"), ("direct", "boussinesq"), ("tree", "boussinesq"), ("tree", "neighbors"),
             ("fft", "local"))] == ["FFTData", "DirectData", "TreeData", "SparseData", "SparseData"]
