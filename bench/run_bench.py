"""`make bench`: operator and full-curve benchmarks, as medians over repeats.

Not part of CI: timings on shared machines are noisy, so the figures are printed, not
asserted. Each section says what it measures; the machine is printed first.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
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


def fft_table(widths=(64, 96, 128, 160, 240, 320, 480), repeats=200):
    """One compiled convolution of a full w x w box (P = fast_len(2w - 1)): median ms on one
    thread and spread over the Numba threads, the choice tfm.kernels.fft.convolve makes.
    The two ways are timed in turn, call by call, so a change of the machine's speed falls
    on both alike."""
    import numba

    from tfm.kernels.fft import buffers, convolve, fast_len, symbol
    rows = []
    for w in widths:
        P = fast_len(2 * w - 1)
        sym = symbol(1e300, 1.0 / 512, 3.8, P)
        src, col, out = buffers(w, P)
        src[:, :w] = np.random.default_rng(0).random((w, w))
        ways = (1, numba.get_num_threads())
        times = {way: [] for way in ways}
        for k in range(repeats + 1):             # call 0 warms up (compilation, plans)
            for way in ways:
                t = time.perf_counter()
                convolve(src, 0, w, col, out, sym, way)
                if k:
                    times[way].append(time.perf_counter() - t)
        rows.append((w, P, *[1e3 * statistics.median(times[way]) for way in ways]))
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


STANDARD = dict(alpha=0.75, k_th=0.02, radius=1.0, shape="paraboloid", max_indent=0.05, step=2.5e-4)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _timed(cmd):
    """Wall seconds of a whole process, and its stdout."""
    t = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=_env(), cwd=ROOT, check=True).stdout
    return time.perf_counter() - t, out


def baseline_run(spacing):
    """(in-process wall as the script reports it, whole-process wall) of bench/baseline.py."""
    whole, out = _timed([sys.executable, os.path.join(ROOT, "bench", "baseline.py"), spacing])
    return float(re.search(r"wall ([0-9.]+) s", out).group(1)), whole


def tfm_in_process(spacing):
    from tfm import Params, simulate
    return simulate(Params.from_dict(dict(STANDARD, spacing=spacing))).summary["wall_time"]


def tfm_run_command(spacing, out):
    """The command line of `tfm run` on the standard curve, its table written to ``out``."""
    return [sys.executable, "-m", "tfm.cli", "run", "--spacing", spacing, "--shape", "paraboloid",
            "--alpha", "0.75", "--k-th", "0.02", "--radius", "1", "--max-indent", "0.05",
            "--step", "2.5e-4", "-q", "-o", out]


def tfm_whole_process(spacing):
    """`tfm run` of the standard curve, plot and Parquet included."""
    with tempfile.TemporaryDirectory() as tmp:
        return _timed(tfm_run_command(spacing, os.path.join(tmp, "curve.parquet")))[0]


def ratio_table(repeats=3, with_256_baseline=True, pairs_256=1, tfm_runs_256=3):
    """The issue's ratios: baseline and tfm interleaved, medians over ``repeats`` pairs
    (``pairs_256`` at 1/256, where the baseline takes minutes; there each pair's tfm side
    is ``tfm_runs_256`` runs, all of which enter the median). Rows: spacing, timing,
    baseline median, tfm median, ratio, baseline runs, tfm runs."""
    from tfm import Params, simulate
    simulate(Params.from_dict(dict(STANDARD, spacing=1 / 16)))        # compile outside timing
    rows = []
    cases = [("1/128", "in-process"), ("1/128", "whole process"), ("1/256", "in-process")]
    for sp, how in cases:
        base, mine = [], []
        skip_base = sp == "1/256" and not with_256_baseline
        for _ in range(pairs_256 if sp == "1/256" else repeats):
            if not skip_base:
                b_in, b_whole = baseline_run(sp)
                base.append(b_in if how == "in-process" else b_whole)
            for _ in range(tfm_runs_256 if sp == "1/256" else 1):
                mine.append(tfm_in_process(sp) if how == "in-process" else tfm_whole_process(sp))
        mb = statistics.median(base) if base else float("nan")
        mt = statistics.median(mine)
        rows.append((sp, how, mb, mt, mb / mt, len(base), len(mine)))
    return rows


def rounds_table(spacings=("1/256", "1/512"), repeats=3):
    """Before/after of the decision-only rounds (tfm.kernels.contact.snap_rounds): every
    round solved to tol (round_tols = ()) against the default, in-process, interleaved."""
    from tfm import Params, simulate
    from tfm.protocol import run
    from tfm.simulate import build_problem
    rows = []
    simulate(Params.from_dict(dict(STANDARD, spacing="1/16")))
    for sp in spacings:
        p = Params.from_dict(dict(STANDARD, spacing=sp))
        times = {True: [], False: []}
        iters = {}
        for _ in range(repeats):
            for loose in (False, True):
                prob, _ = build_problem(p)
                if not loose:
                    prob.round_tols = ()
                t = time.perf_counter()
                out = run(p, prob)
                times[loose].append(time.perf_counter() - t)
                iters[loose] = out.solver_iters
        a, b = statistics.median(times[False]), statistics.median(times[True])
        rows.append((sp, a, iters[False], b, iters[True], a / b))
    return rows


def old_engine_table(spacings=("1/128", "1/256"), repeats=3):
    """Before/after in one run: the old Python engine (tests/reference_engine.py, the code
    of main before the compiled engine) against tfm.simulate, interleaved."""
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from reference_engine import reference_curve
    from tfm import Params, simulate
    rows = []
    for sp in spacings:
        p = Params.from_dict(dict(STANDARD, spacing=sp))
        simulate(p.replace(spacing=1 / 16))
        reference_curve(p.replace(spacing=1 / 16))
        old, new = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            reference_curve(p)
            old.append(time.perf_counter() - t)
            new.append(simulate(p).summary["wall_time"])
        rows.append((sp, statistics.median(old), statistics.median(new),
                     statistics.median(old) / statistics.median(new)))
    return rows


_CHILD = """
import json, resource, sys, time
from tfm import Params, simulate
p = Params.from_dict(dict({std}, spacing={sp!r}))
simulate(p.replace(spacing=1 / 16))
c0 = time.process_time()
res = simulate(p)
cpu = time.process_time() - c0
s = res.summary
print(json.dumps(dict(wall=s["wall_time"], cpu=cpu, solves=s["n_solves"],
      iters=s["solver_iters"], pull_off=s["pull_off_force"], side=s["grid_side"],
      rss=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, threaded=s["threaded_steps"],
      solved=int((res.curve["solver_iters"] > 0).sum()))))
"""


def scale_table(spacings=("1/64", "1/128", "1/256", "1/512", "1/1024"), repeats=3):
    """One subprocess per spacing and repeat: wall, solves, CG iterations, CPU/wall, the
    steps the thread choice ran threaded, peak RSS. The repeats go round all spacings in
    turn, so that those of one spacing lie minutes apart, not inside one slow spell of the
    machine; a row per run, then the medians."""
    runs = {sp: [] for sp in spacings}
    for k in range(repeats):
        for sp in spacings:
            code = _CHILD.format(std=STANDARD, sp=sp)
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 env=_env(), cwd=ROOT, check=True).stdout
            r = json.loads(out.strip().splitlines()[-1])
            r["cpu_wall"] = r["cpu"] / r["wall"]
            runs[sp].append(r)
            print(f"| {k + 1} | {time.strftime('%H:%M:%S')} | {sp} | {r['side']}^2 | {r['wall']:.2f} | "
                  f"{r['solves']} | {r['iters']} | {r['cpu_wall']:.2f} | {r['threaded']} / {r['solved']} | "
                  f"{r['rss'] / 1024:.0f} | {r['pull_off']:.10g} |", flush=True)
    med = lambda sp, key: statistics.median(r[key] for r in runs[sp])  # noqa: E731
    print(f"\n## Medians over {repeats} run(s) per spacing\n")
    print("| spacing | grid | wall s | solves | CG iterations | CPU/wall | peak RSS MiB | pull-off |")
    print("|---|---|---|---|---|---|---|---|")
    for sp in spacings:
        r = runs[sp][0]
        print(f"| {sp} | {r['side']}^2 | {med(sp, 'wall'):.2f} | {r['solves']} | {r['iters']} | "
              f"{med(sp, 'cpu_wall'):.2f} | {med(sp, 'rss') / 1024:.0f} | {r['pull_off']:.10g} |", flush=True)
    for sp in spacings:
        if len({(r["solves"], r["iters"], r["pull_off"]) for r in runs[sp]}) > 1:
            print(f"\nWARNING: {sp}: solves, CG iterations or pull-off differ between repeats")
    return runs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats")
    ap.add_argument("--only", choices=["ratios", "old", "rounds", "fft", "operators", "curves", "tree"], default=None)
    ap.add_argument("--scale", action="store_true",
                    help="only the scaling table 1/64 ... 1/1024 (one subprocess per spacing and run, medians)")
    ap.add_argument("--max-spacing", default="1/1024", help="--scale: finest spacing")
    ap.add_argument("--scale-repeats", type=int, default=3,
                    help="--scale: runs per spacing, taken in turn (1/1024 takes 1.5-2 min each)")
    ap.add_argument("--no-baseline-256", action="store_true",
                    help="skip the plain SciPy baseline at 1/256 (about 2 min)")
    ap.add_argument("--repeats", type=int, default=3, help="A/B pairs per ratio")
    ap.add_argument("--pairs-256", type=int, default=1,
                    help="A/B pairs at 1/256 (each: one baseline run, three tfm runs)")
    args = ap.parse_args(argv)
    print(f"# tfm benchmarks\n\nmachine: {machine()}\n")
    if args.scale:
        print("## Standard curve, one process per spacing and run (CPU/wall = cores busy; "
              "threaded = steps with a solve that the thread choice ran on all threads)\n")
        print("| run | time | spacing | grid | wall s | solves | CG iterations | CPU/wall "
              "| threaded / solved steps | peak RSS MiB | pull-off |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        all_sp = ("1/64", "1/128", "1/256", "1/512", "1/1024")
        scale_table(all_sp[: all_sp.index(args.max_spacing) + 1], args.scale_repeats)
        return
    if args.only in (None, "ratios"):
        print("## Against the plain SciPy script (bench/baseline.py), interleaved, medians\n")
        print("| spacing | timing | baseline s | tfm s | ratio | baseline runs | tfm runs |")
        print("|---|---|---|---|---|---|---|")
        for sp, how, b, t, ratio, kb, kt in ratio_table(args.repeats, not args.no_baseline_256,
                                                        args.pairs_256):
            print(f"| {sp} | {how} | {b:.2f} | {t:.2f} | {ratio:.1f}x | {kb} | {kt} |", flush=True)
        print()
    if args.only in (None, "old"):
        print("## Before/after: the old Python engine (tests/reference_engine.py) against tfm, "
              "in-process, interleaved, medians\n")
        print("| spacing | old engine s | tfm s | speed-up |")
        print("|---|---|---|---|")
        for sp, o, t, ratio in old_engine_table(repeats=args.repeats):
            print(f"| {sp} | {o:.2f} | {t:.2f} | {ratio:.1f}x |")
        print()
    if args.only in (None, "rounds"):
        print("## Decision-only rounds at config.ROUND_TOLS against every round at tol, in-process, "
              "interleaved, medians\n")
        print("| spacing | all at tol s | CG iterations | loose rounds s | CG iterations | speed-up |")
        print("|---|---|---|---|---|---|")
        for sp, a, ia, b, ib, ratio in rounds_table(("1/128", "1/256") if args.quick else ("1/256", "1/512"),
                                                    repeats=args.repeats):
            print(f"| {sp} | {a:.2f} | {ia} | {b:.2f} | {ib} | {ratio:.2f}x |")
        print()
    if args.only in (None, "fft"):
        import numba
        print(f"## One compiled convolution: one thread against {numba.get_num_threads()} "
              "(median ms; threaded from P = 192)\n")
        print("| box w | P | 1 thread | threaded | ratio |")
        print("|---|---|---|---|---|")
        for w, P, t1, tn in fft_table(repeats=50 if args.quick else 200):
            print(f"| {w} | {P} | {t1:.3f} | {tn:.3f} | {t1 / tn:.2f}x |")
        print()
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
