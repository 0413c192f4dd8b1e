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

# Relative residuals at which a solve whose only use is to decide which springs snap or
# enter stops to ask whether its decisions are already certain (tfm.kernels.contact.
# snap_rounds): accepted only when a rigorous bound shows that a tol-solve would decide the
# same; otherwise CG carries on, without restarting, to the next level and then to tol.
# The last round of every step is solved to tol. A stop costs a pass over the contact set
# (the snap check needs F alone); the field u = C F, which the entries need, is computed
# only once the snaps are certain (beside the next round's solve when threaded), and where
# nothing snaps not above FIELD_LEVEL. CG iterations of the standard curve (2026-11-28):
# 1/256, (1e-7,) 6900, these 6194; 1/128, 3603 and 3236. At 1/256 the snaps were certain
# in 728 of 1187 stops at 1e-5, and where springs snapped, the entries were too (206 of 206).
ROUND_TOLS = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
# The loosest of those levels at which a round where no spring snaps computes the field to
# decide its entries: at 1e-5 and 1e-6 most such fields left entries in doubt (1/256: 179
# of 297 and 114 of 180), at 1e-7 22 of 117.
FIELD_LEVEL = 1e-7

# While the contact set does not change, F is linear in d: F(d) = F(d0) + (d - d0) C_SS^-1 1
# (tfm.solver.ContactState._predict, Problem.skip_solves): once the set has survived two
# steps, the base F(d0) and the unit response are solved to SKIP_TOL times tol, so that the
# residual of a prediction stays within tol for many steps (solved to tol, the bound failed
# at the first step: no faster). Standard curve, threaded, 3 runs each in one process
# (2026-11-28): 1/256 1.43-1.46 s against 1.49-1.51 s, 1315 -> 1100 solves (the receding
# contact's 217 steps before its first snap are predicted); 1/128 0.272 s either way;
# 1/512 within 1 %. Forces within 1.1e-10 of the solved ones, the same contact counts.
SKIP_TOL = 0.1
# ... unless SKIP_TOL * tol is below this: a solve cannot reach it in double precision (the
# solves reach 1e-15 at best: params.MIN_TOL), so the set is solved step by step.
SKIP_MIN_TOL = 1e-14


# Box size P from which the compiled FFT cuts its stages into one part per Numba thread
# (when there are more than one: NUMBA_NUM_THREADS=1 keeps a run on one core, as campaign
# workers do). Since the spectra are stored transposed (tfm.kernels.fft), each thread's
# columns are one block of memory, and two threads pay from P ~ 80: one convolution on the
# quiet 2-core VM, medians of 2000 (2026-11-29), P = 64 12.9 us on one thread against
# 13.7 us on two, P = 96 26.9 against 21.9, P = 128 46.8 against 32.2, P = 192 101 against
# 59. (With the columns strided, as before, two threads gained only 1.10-1.18x at P = 192-
# 960, and the threshold was 192.) Standard curve, 8 interleaved pairs against 192: 1/256
# 1.06x, 1/128 1.05x (`python -m bench.ab_commits`); 64 and 128 gave no more. Under load,
# or when the OpenMP worker must be woken between parallel regions, threads can cost more
# than they save, so the compiled solve picks the mode from its own steps
# (tfm.solver.ThreadChoice); the Python-level FFTOperator.apply times both ways once at
# start (tfm.kernels.fft.threads_pay).
FFT_THREADED_SIZE = 96

# ... but a run uses a second thread at all only if its whole grid's box is at least this
# large (tfm.solver.ContactState). A smaller grid's curve is short and gains little from
# threads (1/128, whole box P = 180: 0.233 against 0.245 s in-process), while its second
# busy core slows whatever runs beside it: `tfm run`'s figure process warms up during
# the curve, and the whole `tfm run` at 1/128 took 1.04-1.16 s with two threads against
# 0.91-0.97 s with one (2026-11-29; without the figure 0.76-0.82 against 0.78-0.84 s).
RUN_THREADED_SIZE = 192


# The FFT preconditioner M = R C^-1 R^T applies the inverse kernel (real space, taken once
# from the whole grid's symbol) wrapped onto a periodic box of P >= w + 2 PRE_BOX_MARGIN,
# not on the image-free box P >= 2 w - 1 of C itself: C^-1 decays like 1/r^3, so the images
# of a box barely wider than the contact cost CG almost nothing, and the box holds about a
# quarter of the cells (tfm.kernels.ops.restrict_pre). A preconditioner needs no exactness,
# only symmetry and positivity (its symbol is floored above zero). CG iterations of the
# standard curve at 1/256 (2026-11-24): exact box 2 w - 1 7130; margin 0 7080, 2 6971,
# 8 7029, 16 7058. (Inverting C's own symbol on a smaller box took 15-50 % more
# iterations in earlier sessions; bench/HISTORY.md.)
PRE_BOX_MARGIN = 2


# Box sizes of the whole-grid field u = C F, as fractions of the whole grid's box
# (P = fast_len(2 n - 1)): the field of a contact takes the smallest rung with no images
# (tfm.kernels.ops.field_on_grid). A ladder, not the exact size, so that a run caches at
# most these symbols (memory: tfm.guards.estimate_memory); a contact in the middle of the
# grid needs about (n + w) / (2 n) of the whole box, so the field costs ~ 1/4 to 1.
FIELD_BOX_FRACTIONS = (0.55, 0.625, 0.7, 0.775, 0.85, 0.925, 1.0)


def fft_workers() -> int:
    """Threads for scipy.fft; follows NUMBA_NUM_THREADS so campaign workers share cores."""
    value = os.environ.get("NUMBA_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS")
    try:
        return max(1, int(value)) if value else (os.cpu_count() or 1)
    except ValueError:
        return 1

# Seconds between checkpoints of a running curve (tfm.checkpoint): at most this much of a
# run is computed again after a crash; a save of a 1/1340 state takes well under a second.
CHECKPOINT_EVERY = 600.0
