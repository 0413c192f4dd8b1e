"""`make bench`: operator and full-curve benchmarks, as medians over repeats.

Not part of CI: timings on shared machines are noisy, so the figures are printed, not
asserted. Each section says what it measures; the machine is printed first.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np


def machine() -> str:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba
    return (f"{platform.node()}: {os.cpu_count()} cores ({cpu}), numba threads "
            f"{numba.get_num_threads()}, python {platform.python_version()}, load avg "
            f"{os.getloadavg()[0]:.2f}")


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up (compilation, FFT plans, symbol caches)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def operator_table(sizes=(128, 256, 512), direct_max=256, repeats=5):
    """Median seconds per application of C to a full field of n x n springs."""
    from tfm import Params
    from tfm.geometry import Layout
    from tfm.operators import DirectOperator, FFTOperator, kernel_spec

    rows = []
    for n in sizes:
        spacing = 1.0 / n
        c = np.arange(n) * spacing
        X, Y = np.meshgrid(c, c, indexing="ij")
        layout = Layout(X.ravel(), Y.ravel(), np.full(n * n, spacing ** 2), spacing, (n, n),
                        np.zeros(n * n, dtype=bool))
        spec = kernel_spec(Params(spacing=spacing, extent=0.5), layout)
        src = np.arange(layout.n)
        f = np.random.default_rng(0).normal(size=layout.n)
        fft = FFTOperator(spec, layout)
        t_fft = median_time(lambda: fft.apply(src, f), repeats)
        t_dir = None
        if n <= direct_max:
            direct = DirectOperator(spec, layout)
            t_dir = median_time(lambda: direct.apply(src, f), max(2, repeats // 2))
        rows.append((layout.n, t_fft, t_dir))
    return rows


def curve_table(spacings=("1/64", "1/128", "1/256"), repeats=3):
    """The issue's curve: paraboloid R = 1, alpha 0.75, k_th 0.02, max_indent 0.05, step 2.5e-4."""
    from tfm import Params, simulate

    rows = []
    for sp in spacings:
        p = Params.from_dict(dict(spacing=sp, alpha=0.75, k_th=0.02, radius=1.0, shape="paraboloid",
                                  max_indent=0.05, step=2.5e-4))
        simulate(p.replace(spacing=1 / 16))  # compile outside the timing
        walls, res = [], None
        for _ in range(repeats):
            res = simulate(p)
            walls.append(res.summary["wall_time"])
        s = res.summary
        rows.append((sp, statistics.median(walls), min(walls), max(walls), s["n_solves"],
                     s["solver_iters"], s["pull_off_force"], s["grid_side"]))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats")
    ap.add_argument("--only", choices=["operators", "curves", "tree"], default=None)
    args = ap.parse_args(argv)
    print(f"# tfm benchmarks\n\nmachine: {machine()}\n")
    if args.only in (None, "operators"):
        sizes = (64, 128) if args.quick else (128, 256, 512)
        print("## Operator: one application of C to a full n x n field (median seconds)\n")
        print("| N | FFT | direct | direct pairs/s |")
        print("|---|---|---|---|")
        for N, t_fft, t_dir in operator_table(sizes, repeats=3 if args.quick else 5):
            d = f"{t_dir:.4f}" if t_dir is not None else "(skipped: O(N^2))"
            rate = f"{N * N / t_dir / 1e9:.2f} G" if t_dir else ""
            print(f"| {round(np.sqrt(N))}^2 | {t_fft:.5f} | {d} | {rate} |")
        print()
    if args.only in (None, "curves"):
        spacings = ("1/64", "1/128") if args.quick else ("1/64", "1/128", "1/256")
        print("## Full adhesive curve (paraboloid R=1, alpha 0.75, k_th 0.02, max_indent 0.05, "
              "step 2.5e-4)\n")
        print("| spacing | median wall s | min | max | solves | CG iterations | pull-off force | grid side |")
        print("|---|---|---|---|---|---|---|---|")
        for sp, med, lo, hi, solves, iters, fmax, side in curve_table(spacings, 2 if args.quick else 3):
            print(f"| {sp} | {med:.2f} | {lo:.2f} | {hi:.2f} | {solves} | {iters} | {fmax:.7g} | {side} |")
        print()
    if args.only in (None, "tree"):
        from bench.bench_tree import markdown, tree_table

        sizes = (64, 128) if args.quick else (64, 128, 256, 512)
        print("## Barnes-Hut tree against the direct sum (RMS and max relative error; median "
              "seconds)\n")
        print(markdown(tree_table(sizes=sizes, repeats=3 if args.quick else 5)))
        print()


if __name__ == "__main__":
    main()
