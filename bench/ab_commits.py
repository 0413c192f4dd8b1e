"""Before/after of two checkouts of tfm on the standard curve, runs interleaved.

    python -m bench.ab_commits OLD_CHECKOUT NEW_CHECKOUT 1/128x5 1/256x5 1/512x3 run:1/128x15

Each ``SPACINGxPAIRS`` runs the curve PAIRS times in each checkout, alternating, one
process per run (PYTHONPATH = the checkout; NUMBA_NUM_THREADS passed through), and prints
the medians of tfm.simulate's wall time, their ratio, the CG iterations, whether the contact
count is equal at every step and how far the pull-offs lie apart. Make a second checkout
with `git worktree add ../old <commit>`; its first run compiles its kernels (not timed:
each child compiles on a 1/16 curve first). ``run:SPACINGxPAIRS`` times whole `tfm run`
processes instead (plot and table included, as `make bench` does), after one untimed
pair that fills both compile caches, and prints the median ratio of the pairs too.
"""
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from bench.run_bench import tfm_run_command

CHILD = r'''
import json, sys
from tfm import Params, simulate
from bench.run_bench import STANDARD
p = Params.from_dict(dict(STANDARD, spacing=sys.argv[1]))
simulate(p.replace(spacing=1 / 16))
r = simulate(p)
s = r.summary
print(json.dumps([s["wall_time"], s["solver_iters"], s["pull_off_force"], r.curve["n_contact"].tolist()]))
'''


def _env(checkout: str) -> dict:
    """A child's environment: tfm from ``checkout``; NUMBA_NUM_THREADS passed through."""
    env = {"PYTHONPATH": os.path.abspath(checkout), "PATH": os.environ.get("PATH", "/usr/bin:/bin")}
    if "NUMBA_NUM_THREADS" in os.environ:
        env["NUMBA_NUM_THREADS"] = os.environ["NUMBA_NUM_THREADS"]
    return env


def run(checkout: str, spacing: str) -> list:
    env = _env(checkout)
    # cwd too: `python -c` puts the working directory before PYTHONPATH
    out = subprocess.run([sys.executable, "-c", CHILD, spacing], capture_output=True, text=True,
                         env=env, cwd=os.path.abspath(checkout), check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def run_command(checkout: str, spacing: str) -> float:
    """Wall seconds of one `tfm run` of the standard curve in ``checkout``."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = tfm_run_command(spacing, os.path.join(tmp, "curve.parquet"))
        t = time.perf_counter()
        subprocess.run(cmd, env=_env(checkout), cwd=tmp, check=True, capture_output=True)
        return time.perf_counter() - t


def whole_process(old: str, new: str, spacing: str, pairs: int) -> None:
    for checkout in (old, new):
        run_command(checkout, spacing)          # compile caches filled, files cached
    a, b = [], []                   # by position: OLD and NEW may be one checkout (an A/A check)
    for _ in range(pairs):
        a.append(run_command(old, spacing))
        b.append(run_command(new, spacing))
    ma, mb = statistics.median(a), statistics.median(b)
    pair = statistics.median(x / y for x, y in zip(a, b))
    print(f"tfm run {spacing}: old {[round(x, 3) for x in a]} median {ma:.3f} s | new "
          f"{[round(x, 3) for x in b]} median {mb:.3f} s | old/new {ma / mb:.2f}x, median of the "
          f"pairs' ratios {pair:.2f}x", flush=True)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 3:
        sys.exit(__doc__)
    old, new, cases = argv[0], argv[1], argv[2:]
    for case in cases:
        if case.startswith("run:"):
            spacing, pairs = case[4:].split("x")
            whole_process(old, new, spacing, int(pairs))
            continue
        spacing, pairs = case.split("x")
        a, b = [], []
        for _ in range(int(pairs)):
            a.append(run(old, spacing))
            b.append(run(new, spacing))
        ma, mb = (statistics.median(r[0] for r in x) for x in (a, b))
        print(f"{spacing}: old {[round(r[0], 2) for r in a]} median {ma:.3f} s ({a[0][1]} CG iterations) | "
              f"new {[round(r[0], 2) for r in b]} median {mb:.3f} s ({b[0][1]}) | old/new {ma / mb:.2f}x | "
              f"n_contact equal at every step: {a[0][3] == b[0][3]} | pull-off relative difference "
              f"{abs(a[0][2] - b[0][2]) / a[0][2]:.1e}", flush=True)


if __name__ == "__main__":
    main()
