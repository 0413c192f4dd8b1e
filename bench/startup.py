"""Start-up time of the light commands (issue 8: under 0.5 s): medians of 11 fresh
processes, wall and CPU, beside a bare `python -c pass`; and the floor of `tfm run` (its
imports and Numba's first cache load, with no curve and no plot).

    python -m bench.startup
"""
from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {
    "python -c pass": ["-c", "pass"],
    "tfm --help": ["-m", "tfm", "--help"],
    "tfm run --help": ["-m", "tfm", "run", "--help"],
    "tfm campaign status": ["-m", "tfm", "campaign", "status", "campaigns/smoke.toml",
                            "--results-dir", "/nonexistent-results"],
    # the floor of `tfm run`: its imports and Numba's first cache load, no curve, no plot
    "tfm run's imports": ["-c", "import tfm.protocol, tfm.simulate, pandas, pyarrow.parquet, tfm.plots; "
                                "from tfm.kernels.fft import fast_len; fast_len(5)"],
}


def main(repeats: int = 11) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    wall = {c: [] for c in COMMANDS}
    cpu = {c: [] for c in COMMANDS}
    for _ in range(repeats):                       # interleaved, so load affects all alike
        for name, args in COMMANDS.items():
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True)
            wall[name].append(time.perf_counter() - start)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu[name].append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; medians of {repeats}")
    for name in COMMANDS:
        print(f"{name:24s} wall {statistics.median(wall[name]):.3f} s  cpu {statistics.median(cpu[name]):.3f} s")


if __name__ == "__main__":
    main()
