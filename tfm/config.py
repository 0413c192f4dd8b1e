"""Numerical settings shared by the package: schema version, Numba flags, named tolerances."""
import os

# Bumped whenever a result column changes meaning; part of every run id.
SCHEMA_VERSION = 1

# Numba: cache compiled kernels on disk so a second process starts in seconds.
NUMBA_OPTS = dict(cache=True, nogil=True, fastmath=False)
PARALLEL_OPTS = dict(NUMBA_OPTS, parallel=True)

# Fixed block length for parallel reductions. Partial sums over fixed blocks, added in
# block order, make every result independent of the thread count (bitwise).
REDUCTION_BLOCK = 4096

# Radius (in spacings) of the truncated inverse-kernel stencil used as CG preconditioner.
STENCIL_RADIUS = 3

# Snap/enter decisions ignore violations smaller than this multiple of the solver's
# residual tolerance, so that round-off cannot make a spring flicker in and out.
DECISION_SLACK = 10.0

# Relative residual of a solve whose only use is to decide which springs snap or enter
# (tfm.kernels.contact.snap_rounds): accepted only when a rigorous bound shows that a
# tol-solve would decide the same; the last round of every step is still solved to tol.
# CG iterations of the standard curve, every round at tol against ROUND_TOL = 1e-6, 1e-7,
# 1e-8: 1/256 8930, 8122, 7431, 7801; 1/512 17566, -, 14070, 14586 (1/128: 4619 at tol,
# 3935 at 1e-6, 4067 at 1e-7, 4351 at 1e-5). Looser values leave more springs unsure,
# and their refinement costs more than the loose solve saved.
ROUND_TOL = 1e-7


# Box size P from which the compiled FFT spreads its fixed chunks over the Numba threads
# (when there are more than one: NUMBA_NUM_THREADS=1 keeps a run on one core, as campaign
# workers do). One convolution, medians of 200 on the quiet 2-core VM (`python -m
# bench.run_bench --only fft`): P = 192, 0.23 ms on 2 threads vs 0.31 ms on one; P = 480,
# 1.26 vs 2.45 ms. Under heavy load a barrier can wait a scheduler slice, so a run also
# times both ways at start (tfm.kernels.fft.threads_pay) and keeps the faster.
FFT_THREADED_SIZE = 192


def fft_workers() -> int:
    """Threads for scipy.fft; follows NUMBA_NUM_THREADS so campaign workers share cores."""
    value = os.environ.get("NUMBA_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS")
    try:
        return max(1, int(value)) if value else (os.cpu_count() or 1)
    except ValueError:
        return 1
