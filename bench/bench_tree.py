"""Accuracy and speed of the Barnes-Hut tree operator against the direct sum.

The sum is the bare 1/r sum (no self term) over N = n^2 points of a planar square
grid, every point both a source and a target, for forces drawn uniformly in [0, 1)
("positive") and in [-1, 1) ("mixed"; the forces cancel, the hard case for a tree).

Errors are relative to the size of the exact field: RMS = ||u - u_ref||_2 / ||u_ref||_2
and max = max |u - u_ref| / rms(u_ref), over all targets for N <= 128^2 and over a
random sample of ``sample`` targets (exact direct sums) above that. Times are medians
of ``repeats`` (and the best build + eval, less sensitive to a busy machine): *build* is everything that depends only on which springs are sources
and targets (subset sort, nodes, boxes, target groups); *eval* is what is repeated
for new forces (moments and the tree walk). The solver's CG iterations pay eval only.

    python -m bench.bench_tree            # the README table
"""
from __future__ import annotations

import os
import platform
import time

import numpy as np

from tfm.geometry import Layout
from tfm.kernels.direct import BOUSSINESQ, direct_sum
from tfm.operators import KernelSpec
from tfm.tree_operator import TreeOperator

SIZES = (64, 128, 256, 512)
THETAS = (0.3, 0.5, 0.7, 1.0)
FULL_REFERENCE_MAX = 128 * 128      # above this, the reference is a sample of targets


def plane_layout(n: int) -> Layout:
    h = 1.0 / n
    c = (np.arange(n) + 0.5) * h
    X, Y = np.meshgrid(c, c, indexing="ij")
    x, y = X.ravel().copy(), Y.ravel().copy()
    return Layout(x, y, np.full(x.size, h * h), h, (n, n), np.zeros(x.size, dtype=bool))


def _times(fn, repeats):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return np.array(times), out


def tree_table(sizes=SIZES, thetas=THETAS, repeats=5, signs=("positive", "mixed"),
               order=None, leaf_size=None, group_size=None, sample=4000, seed=0):
    """One row per (N, forces, theta): errors against the direct sum, build and eval times."""
    rows = []
    kw = {k: v for k, v in dict(order=order, leaf_size=leaf_size, group_size=group_size).items()
          if v is not None}
    for n in sizes:
        lay = plane_layout(n)
        N = lay.n
        spec = KernelSpec(BOUSSINESQ, np.inf, np.zeros(N))
        src = np.arange(N, dtype=np.int64)
        rng = np.random.default_rng(seed)
        if N <= FULL_REFERENCE_MAX:
            tgt_ref = src
        else:
            tgt_ref = np.sort(rng.choice(N, size=min(sample, N), replace=False)).astype(np.int64)
        for sign in signs:
            f = rng.uniform(0.0, 1.0, N) if sign == "positive" else rng.uniform(-1.0, 1.0, N)
            t0 = time.perf_counter()
            ref = direct_sum(lay.x, lay.y, spec.diag, src, f, tgt_ref, BOUSSINESQ, np.inf)
            t_direct = time.perf_counter() - t0
            ref_rms = np.sqrt(np.mean(ref ** 2))
            for theta in thetas:
                op = TreeOperator(spec, lay, theta=theta, **kw)
                op.evaluate(op.build_sources(src[:64]), op.build_targets(src[:64]), f[:64])  # JIT warm-up
                t_build, (tree, groups) = _times(
                    lambda: (op.build_sources(src), op.build_targets(None)), repeats)
                t_eval, u = _times(lambda: op.evaluate(tree, groups, f), repeats)
                best = float((t_build + t_eval).min())
                t_build, t_eval = float(np.median(t_build)), float(np.median(t_eval))
                err = u[tgt_ref] - ref
                rows.append(dict(
                    N=N, side=n, forces=sign, theta=theta, order=op.order,
                    rms=float(np.sqrt(np.mean(err ** 2)) / ref_rms),
                    max=float(np.abs(err).max() / ref_rms),
                    build_s=t_build, eval_s=t_eval, total_s=t_build + t_eval, best_total_s=best,
                    n_ref=int(tgt_ref.size),
                    direct_s_est=t_direct * N / tgt_ref.size))
    return rows


def machine() -> str:
    from numba import config as nbconfig
    return (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
            f"Numba {nbconfig.NUMBA_NUM_THREADS} threads, Python {platform.python_version()}")


def markdown(rows) -> str:
    lines = ["| N | forces | theta | RMS error | max error | build (s) | eval (s) | total (s) | best total (s) | direct (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['side']}² | {r['forces']} | {r['theta']:.1f} | {r['rms']:.1e} | {r['max']:.1e} | "
                     f"{r['build_s']:.3f} | {r['eval_s']:.3f} | {r['total_s']:.3f} | {r['best_total_s']:.3f} | "
                     f"{r['direct_s_est']:.1f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--thetas", type=float, nargs="+", default=list(THETAS))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--order", type=int, default=None)
    ap.add_argument("--leaf", type=int, default=None)
    ap.add_argument("--group", type=int, default=None)
    a = ap.parse_args()
    rows = tree_table(a.sizes, a.thetas, a.repeats, order=a.order, leaf_size=a.leaf, group_size=a.group)
    print(f"Machine: {machine()}\n")
    print(markdown(rows))
