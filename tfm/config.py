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


# Box size P from which the compiled FFT spreads its fixed chunks over Numba threads.
# Every parallel stage ends in a barrier; on a loaded machine a barrier waits a scheduler
# slice (ms). Measured on the shared 2-core VM (omp layer, load ~5): 2 threads took
# 20 ms a convolution at P = 240 against 0.7 ms on one, and 37 ms against 14 ms at
# P = 625. So by default only the largest boxes (1/1024 grids) are threaded.
FFT_THREADED_SIZE = int(os.environ.get("TFM_FFT_THREADED_SIZE", "1024"))


def fft_workers() -> int:
    """Threads for scipy.fft; follows NUMBA_NUM_THREADS so campaign workers share cores."""
    value = os.environ.get("NUMBA_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS")
    try:
        return max(1, int(value)) if value else (os.cpu_count() or 1)
    except ValueError:
        return 1
