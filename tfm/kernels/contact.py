"""Algorithm 1 of the paper (Sec. 2.1) in compiled code: the contact solve (PCG) and the
snapping rounds of one dilatation step, for every operator.

For a fixed contact set S the forces solve C_SS F = d - x0_S (paper, Eq. 1), a symmetric
positive-definite system. Each solve restricts the operator and the preconditioner to S
once (tfm.kernels.ops: the box, FFT size and symbols, or the trees, and the work buffers)
before the first CG iteration, and all iterations share them. Dot products are summed in
fixed blocks (blocked_dot), transforms and tree walks in fixed orders, so the iterates do
not depend on the number of threads.

A round whose solve only decides which springs change stops at the looser residuals of
config.ROUND_TOLS, when a rigorous bound shows a tol-solve would decide the same, and
carries on from there if not (snap_rounds; the CG state is kept, cg_run).
"""
import numpy as np
from numba import njit, prange
from numba.extending import overload

from ..config import NUMBA_OPTS, PARALLEL_OPTS
from .atomic import atomic_load, atomic_store
from .fft import fast_len
from .grid import abs_max, blocked_dot, grid_reach, index_box
from .ops import (PRE_FFT, FFTData, apply_set, cached_symbol, field, field_box, field_on_grid, pre_len,
                  pre_symbol, precondition, restrict, restrict_pre)

# slots of the integer statistics array
(S_SOLVES, S_ITERS, S_FAILURES, S_ROUNDS, S_SNAPPED, S_ENTERED, S_EXCEEDED, S_LAST_ITERS,
 S_REFINES, S_AHEAD, S_DROPPED, S_GUESS_KEPT, S_GUESS_DROPPED, S_PREPARED, S_UNIT_ITERS) = range(15)
N_STATS = 15
# slots of the float statistics array
F_MAX_RES, F_LAST_RES, F_LAST_BNORM, F_BASE_RES, F_UNIT_RES = range(5)
N_FSTATS = 5


@njit(**NUMBA_OPTS)
def cg_workspace(op, pre, idx):
    """The operator and the preconditioner restricted to the contact set idx, built once
    per solve (tfm.kernels.ops.restrict, restrict_pre)."""
    return restrict(op, idx), restrict_pre(pre, idx)


@njit(**NUMBA_OPTS)
def cg_start(op, ws, idx, b, x, Ax0, has_Ax0, vecs):
    """CG state for C_SS x = b from the guess x: (r, z, p, Ap, sc) with sc = [r.z, ||r||,
    ||b||, phase]; phase 0: not started, 1: p is the next direction, 2: r was updated last
    and z, p still have to follow. ``Ax0`` = C x when has_Ax0 saves the first application
    (it may be r's own row). r, z, p, Ap are the first idx.size entries of the rows of
    ``vecs`` (4 x N: snap_rounds keeps them for the run)."""
    m = idx.size
    r, z, p, Ap = vecs[0, :m], vecs[1, :m], vecs[2, :m], vecs[3, :m]
    if has_Ax0:
        for k in range(m):
            r[k] = b[k] - Ax0[k]
    else:
        nonzero = False
        for k in range(m):
            if x[k] != 0.0:
                nonzero = True
                break
        if nonzero:
            apply_set(op, ws[0], idx, x, Ap)
            for k in range(m):
                r[k] = b[k] - Ap[k]
        else:
            r[:] = b
    sc = np.array([0.0, np.sqrt(blocked_dot(r, r)), np.sqrt(blocked_dot(b, b)), 0.0])
    return r, z, p, Ap, sc


@njit(**NUMBA_OPTS)
def contact_indices(contact, out):
    """The springs in contact, in order: the first entries of ``out``."""
    m = 0
    for i in range(contact.size):
        if contact[i]:
            out[m] = i
            m += 1
    return out[:m]


@njit(**NUMBA_OPTS)
def _next_direction(pre, ws, r, z, p, rz, idx):
    """z = M r, then p = z + (r.z / rz) p; returns the new r.z."""
    precondition(pre, ws[1], idx, r, z)
    rz_new = blocked_dot(r, z)
    beta = rz_new / rz
    for k in range(idx.size):
        p[k] = z[k] + beta * p[k]
    return rz_new


@njit(**NUMBA_OPTS)
def cg_run(op, pre, ws, state, idx, x, tol, max_iter, stop=None):
    """Carry PCG on from ``state`` until ||r|| <= tol ||b|| or max_iter iterations in this
    call. A later call with a smaller tol continues the same Krylov sequence (no restart),
    so a solve stopped early for a decision loses nothing when it must go on. ``stop``: an
    int64 array whose stop[0] another thread may set to end the solve after the part of the
    iteration in progress (the application and update, or the preconditioning; not
    converged). Returns (iterations, converged, relative residual)."""
    r, z, p, Ap, sc = state
    m = idx.size
    bnorm = sc[2]
    if bnorm == 0.0:
        x[:] = 0.0
        return 0, True, 0.0
    if sc[1] <= tol * bnorm:
        return 0, True, sc[1] / bnorm
    if sc[3] == 0.0:
        precondition(pre, ws[1], idx, r, z)
        p[:] = z
        sc[0] = blocked_dot(r, z)
    elif sc[3] == 2.0:
        # the last call stopped after updating r: finish that iteration's direction
        sc[0] = _next_direction(pre, ws, r, z, p, sc[0], idx)
    sc[3] = 1.0
    for it in range(1, max_iter + 1):
        if stop is not None and atomic_load(stop, 0) != 0:
            return it - 1, False, sc[1] / bnorm
        apply_set(op, ws[0], idx, p, Ap)
        pAp = blocked_dot(p, Ap)
        if pAp <= 0.0:
            # only possible if C is not positive definite on this set (checked upstream)
            return it, False, sc[1] / bnorm
        step = sc[0] / pAp
        for k in range(m):
            x[k] += step * p[k]
            r[k] -= step * Ap[k]
        sc[1] = np.sqrt(blocked_dot(r, r))
        if sc[1] <= tol * bnorm:
            sc[3] = 2.0
            return it, True, sc[1] / bnorm
        if stop is not None and atomic_load(stop, 0) != 0:
            # checked here too, not only before the application: the thread that set it
            # waits for this one, on average half a segment (2026-11-29)
            sc[3] = 2.0
            return it, False, sc[1] / bnorm
        sc[0] = _next_direction(pre, ws, r, z, p, sc[0], idx)
    return max_iter, False, sc[1] / bnorm


@njit(**NUMBA_OPTS)
def solve_on_set(op, pre, idx, b, x, Ax0, has_Ax0, tol, max_iter, u, with_field):
    """PCG for C_SS x = b on the contact set idx (sorted flat indices), from the guess x
    (overwritten), stopping at ||b - C x|| <= tol ||b||. ``Ax0`` = C x when has_Ax0 saves
    the first application. With with_field, u (one entry per spring) receives the field
    C x (x on idx, 0 elsewhere). Returns (iterations, converged, relative residual)."""
    ws = cg_workspace(op, pre, idx)
    state = cg_start(op, ws, idx, b, x, Ax0, has_Ax0, np.empty((4, idx.size)))
    res = cg_run(op, pre, ws, state, idx, x, tol, max_iter)
    if with_field:
        field(op, ws[0], idx, x, u)
    return res


@njit(**NUMBA_OPTS)
def _snap_check(idx, Fc, f_th, rel, bf, marks):
    """The snap rule of Algorithm 1 on the contact set idx with forces Fc: marks[i] = 1 if
    spring i snaps (F_i above F_th,i by more than the slack, rel times the largest contact
    force: violations at the level of the solve's own error are ignored), else 0. With a
    bound bf > 0 on the distance to the tolerance-tol solution, also counts the springs
    whose fate that distance could change. Visits the contact set only: a solve's decision
    stop needs F alone. Returns (snapping, unsure, worst snap)."""
    slack_f = rel * abs_max(Fc[:idx.size])
    n_over = 0
    unsure = 0
    worst = -1
    worst_k = -1
    for k in range(idx.size):
        i = idx[k]
        marks[i] = 0
        g = Fc[k] - (f_th[i] + slack_f)
        if g > 0.0:
            marks[i] = 1
            n_over += 1
            if worst < 0 or Fc[k] - f_th[i] > Fc[worst_k] - f_th[worst]:
                worst = i
                worst_k = k
        if abs(g) <= bf:
            unsure += 1
    return n_over, unsure, worst


@njit(**NUMBA_OPTS)
def _classify(d, idx, contact, F, u, x0, f_th, rel, bf, bu, marks):
    """Both rules of Algorithm 1: marks[i] = 1 if spring i snaps (_snap_check), 2 if it
    enters (x0_i + u_i above d by more than rel times the largest of |d| and |u|), 0 if it
    stays; idx is the contact set. With bounds bf, bu > 0 on the distance to the
    tolerance-tol solution (forces, displacements), also counts the springs whose fate that
    distance could change. Returns (snapping, entering, unsure, worst snap, worst entry)."""
    n_over, unsure, worst_over = _snap_check(idx, F[idx], f_th, rel, bf, marks)
    slack_u = rel * max(abs(d), abs_max(u))
    n_into = 0
    worst_into = -1
    for i in range(contact.size):
        if contact[i]:
            continue
        marks[i] = 0
        g = x0[i] + u[i] - (d + slack_u)
        if g > 0.0:
            marks[i] = 2
            n_into += 1
            if worst_into < 0 or x0[i] + u[i] > x0[worst_into] + u[worst_into]:
                worst_into = i
        if abs(g) <= bu:
            unsure += 1
    return n_over, n_into, unsure, worst_over, worst_into


@njit(**NUMBA_OPTS)
def extrapolate(F, u, slope, uslope, contact, c, guess, u_guess):
    """The warm start of a step: guess = F + c slope, and u_guess = u + c uslope if slope
    vanishes off the contact set (returned: then u_guess = C guess); one pass instead of
    NumPy's six whole-grid temporaries (with difference_quotients and no copies that only
    skip_solves reads, the Python part of a 1/256 curve's steps went from 0.09 to 0.055 s,
    2026-11-28)."""
    known = True
    for i in range(F.size):
        guess[i] = F[i] + c * slope[i]
        if slope[i] != 0.0 and not contact[i]:
            known = False
    if known:
        for i in range(F.size):
            u_guess[i] = u[i] + c * uslope[i]
    return known


@njit(**NUMBA_OPTS)
def predicted(Fb, ub, x, w, c, F, u):
    """F = Fb + c x and u = ub + c w, in place: a step of an unchanged contact set."""
    for i in range(F.size):
        F[i] = Fb[i] + c * x[i]
        u[i] = ub[i] + c * w[i]


@njit(**NUMBA_OPTS)
def rhs_norm(contact, x0, d):
    """||d - x0|| over the contact set: blocked_dot of the gathered vector, so the same
    bits as the ||b|| of a solve on that set (cg_start)."""
    b = np.empty(contact.size)
    m = 0
    for i in range(contact.size):
        if contact[i]:
            b[m] = d - x0[i]
            m += 1
    return np.sqrt(blocked_dot(b[:m], b[:m]))


@njit(**NUMBA_OPTS)
def difference_quotients(F, u, F0, u0, dd, slope, uslope):
    """slope = (F - F0) / dd and uslope = (u - u0) / dd, in place."""
    for i in range(F.size):
        slope[i] = (F[i] - F0[i]) / dd
        uslope[i] = (u[i] - u0[i]) / dd


@njit(**NUMBA_OPTS)
def _likely_changes(contact, marks, x0, u_guess, d, rel, entries, pred):
    """The round's changes as they will likely be: its snaps (``marks`` on the contact set,
    already certain) and, with ``entries``, the springs off it that the field of the step's
    guess, u_guess, puts into the flat (the slack as _classify's). pred[i] = 1, 2 or 0 as
    marks; returns how many change. Only a guess: _field_beside_solve checks it."""
    slack_u = 0.0
    if entries:
        slack_u = rel * max(abs(d), abs_max(u_guess))
    n = 0
    for i in range(contact.size):
        pred[i] = 0
        if contact[i]:
            if marks[i] == 1:
                pred[i] = 1
                n += 1
        elif entries and x0[i] + u_guess[i] - (d + slack_u) > 0.0:
            pred[i] = 2
            n += 1
    return n


@njit(**NUMBA_OPTS)
def _next_set(contact, pred, F, x0, d, idx_out, b, Fc):
    """The next round's contact set if the changes in ``pred`` (_likely_changes) are the round's:
    its indices (the first entries of idx_out), b = d - x0 and the guess F on it (what the
    next round builds: this round's F with the snapped springs at 0, or after a first round
    that only brings springs in, the step's guess; either is 0 off the set)."""
    m = 0
    for i in range(contact.size):
        if (contact[i] and pred[i] != 1) or pred[i] == 2:
            idx_out[m] = i
            b[m] = d - x0[i]
            Fc[m] = F[i]
            m += 1
    return idx_out[:m]


@njit(**PARALLEL_OPTS)
def _field_beside_solve(op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu, marks,
                        pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts, cg_out,
                        stop):
    """Two tasks on two threads: the field u = C F of this round and its decisions, beside
    the start of the next round's solve (to its first decision level; Ax2 = C Fc2 when
    has_Ax2 saves its first application) on the set idx2, the one the predicted changes
    ``pred`` make (_likely_changes, _next_set). Each task is single-threaded (op1, pre1);
    they share no buffer: the field has its own, the solve the box buffers, which this round
    needs again only if the prediction fails (then the caller restricts again). When the
    field's task is done it stops the solve (stop[0]) at its next check (cg_run): decisions
    other than the predicted ones, or in doubt, make it useless, and otherwise the caller
    carries it on with both threads. Results go to counts (n_over,
    n_into, unsure, worst snap, worst entry, prediction right), cg_out (iterations,
    converged, residual, stopped early) and sc2. (The field is the FFT operator's own: a
    tuple such as a workspace cannot enter a prange.)"""
    for t in prange(2):
        if t == 0:
            field_on_grid(idx, Fc, op1.n, op1.syms, op1.cut2, op1.spacing, op1.diag[0], op1.src,
                          op1.col, op1.out, u, op1.threads)
            c = _classify(d, idx, contact, F, u, x0, f_th, rel, e, eu, marks)
            for k in range(5):
                counts[k] = c[k]
            right = c[2] == 0
            for i in range(marks.size):
                if marks[i] != pred[i]:
                    right = False
                    break
            counts[5] = right
            # either way the solve stops at its next check: dropped, or carried on by the
            # caller with both threads on its transforms
            atomic_store(stop, 0, 1)
        else:
            ws2 = cg_workspace(op1, pre1, idx2)
            st = cg_start(op1, ws2, idx2, b2, Fc2, Ax2, has_Ax2, vecs2)
            it, conv, res = cg_run(op1, pre1, ws2, st, idx2, Fc2, lev, max_iter, stop)
            for k in range(4):
                sc2[k] = st[4][k]
            cg_out[0] = it
            cg_out[1] = 1.0 if conv else 0.0
            cg_out[2] = res
            cg_out[3] = 1.0 if not conv and atomic_load(stop, 0) != 0 else 0.0   # stopped


def field_beside_solve(op, op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu,
                       marks, pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts, cg_out,
                       stop):
    """_field_beside_solve for the FFT operator (compiled code only; snap_rounds calls it
    with ``overlap`` only, which the caller sets for FFTData alone)."""
    raise NotImplementedError


@overload(field_beside_solve, jit_options=NUMBA_OPTS)
def _field_beside_solve_impl(op, op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu,
                             marks, pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts,
                             cg_out, stop):
    if getattr(op, "instance_class", None) is not FFTData:
        # never called (no overlap for the other operators), and so not compiled for them
        def stub(op, op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu,
                 marks, pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts, cg_out,
                 stop):
            pass
        return stub

    def impl(op, op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu,
             marks, pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts, cg_out,
             stop):
        # every symbol the two tasks look up is made here: the typed dicts must not take
        # insertions from two threads at once
        n = op.n
        cached_symbol(op.syms, field_box(n, 2 * grid_reach(n, idx) + 1), op.cut2, op.spacing, op.diag[0])
        w = index_box(n, idx2)[2]
        cached_symbol(op.syms, fast_len(2 * w - 1), op.cut2, op.spacing, op.diag[0])
        if pre1.kind == PRE_FFT:
            pre_symbol(pre1.psyms, pre1.kinv, pre1.floor, pre_len(w))
        stop[0] = 0
        _field_beside_solve(op1, pre1, idx, Fc, u, d, contact, F, x0, f_th, rel, e, eu,
                            marks, pred, idx2, b2, Fc2, Ax2, has_Ax2, vecs2, sc2, lev, max_iter, counts,
                            cg_out, stop)
    return impl


@njit(**NUMBA_OPTS)
def snap_rounds(d, contact, F, u, guess, u_guess, has_u_guess, solved, x0, f_th, op, pre, tol,
                max_iter, max_rounds, single, slack, round_tols, field_level, bound_f, bound_u, stats,
                fstats, work, iwork, flags, overlap, guess_entries, op1, pre1, prepare_tol, slope,
                has_slope, base, unit):
    """The rounds of one dilatation step d (Algorithm 1): solve on the contact set, then
    snap every spring above its threshold and bring in every penetrating one (or only the
    worst, ``single``), until nothing changes or max_rounds is reached.

    Decision levels. A round's solve stops at each of the loose relative residuals
    ``round_tols`` (descending, all > tol) in turn and asks whether the decisions are
    already certain. A tol-solve's iterate has a residual of at most tol ||b||, so it
    differs from this one by at most bound_f (||r|| + tol ||b||) in any F_k and by at most
    bound_u times that in u_i off the set (tfm.solver.decision_bounds: for every set). If
    no spring lies within those bounds of its decision line and some spring changes, the
    round's decisions are taken there; the sequence of contact sets is the one tol-solves
    give. Otherwise CG carries on (same Krylov sequence, no restart) to the next level,
    and finally to tol: the last round of every step is a tol-solve. The snap check needs
    only F (and only the contact set: _snap_check), so the field u is computed at a level
    only once no snap is in doubt, and where no spring snaps, not at levels above
    ``field_level``: there the entries are mostly still in doubt. An empty round_tols (or
    bound_f <= 0) solves every round to tol.

    Overlap (``overlap``: the FFT operator on two or more threads). Once a round's snaps are
    certain, the field that decides its entries and the next round's solve to its first
    level run side by side, each on one thread (op1, pre1: the operator and preconditioner
    on one thread). The solve is on the set the round's changes will likely make: the
    certain snaps, and in a step's first round the entries that the field of the step's
    guess predicts (_likely_changes; only with ``guess_entries``: S_GUESS_KEPT and
    S_GUESS_DROPPED count how those fared). It is kept when the field's decisions are
    those, which is nearly always the case while a contact recedes, else stopped and
    dropped. It is the computation the next round makes on one thread, so the numbers are
    the same either way, bit for bit.

    ``op`` and ``pre`` are the operator's and the preconditioner's data (tfm.kernels.ops).
    ``work`` (2 x 6 x N floats, two sets of: b, the guess, then cg_start's r, z, p, Ap),
    ``iwork`` (2 x N integers: the contact set; one set for this round, one for the next)
    and ``flags`` (2 x N int8: the changes, and the changes predicted) are work space kept
    for the run. contact, F, u are updated in place (one entry per spring). ``guess`` is
    the first solve's guess for F; ``u_guess`` = C guess when has_u_guess. A first round
    that only brings springs in is followed by a round from that same guess (0 on the new
    springs), not from its own F. ``solved``: F and u already hold the solution on the
    current set (the first solve is skipped). Counts go to ``stats``; ``fstats`` holds the
    largest relative residual of the tol-solves (updated), then the relative residual and
    ||b|| of the last solve.

    With ``prepare_tol`` > 0, a step that changes nothing ends with what predicts the next
    steps on its set (tfm.solver.ContactState._predict): prepare_predictions. Here, not
    from Python, so that a run loads one compiled library the fewer."""
    N = contact.size
    marks, pred = flags[0], flags[1]       # the round's changes, and as predicted
    loose_ok = round_tols.size > 0 and bound_f > 0.0 and not single
    first = True
    n_over = n_into = unsure = wo = wi = 0
    cur = 0                                # which of the two work sets this round uses
    ahead = False                          # the next round's solve to its first level is done
    counts = np.zeros(6, dtype=np.int64)
    stop = np.zeros(1, dtype=np.int64)
    cg_out = np.zeros(4)
    sc_ahead = np.zeros(4)
    sc_m = 0
    while True:
        decided = False
        res = 0.0
        wk = work[cur]
        if ahead:
            idx = iwork[cur][:sc_m]
        else:
            idx = contact_indices(contact, iwork[cur])
        if not (first and solved):
            if idx.size == 0:
                F[:] = 0.0
                u[:] = 0.0
                stats[S_LAST_ITERS] = 0
                fstats[F_LAST_RES] = 0.0
                fstats[F_LAST_BNORM] = 0.0
            else:
                m = idx.size
                b, Fc, Ax0 = wk[0, :m], wk[1, :m], wk[2, :m]
                if not ahead:
                    for k in range(m):
                        b[k] = d - x0[idx[k]]
                        Fc[k] = guess[idx[k]]
                        if has_u_guess:
                            Ax0[k] = u_guess[idx[k]]
                ws = cg_workspace(op, pre, idx)
                if ahead:
                    state = (wk[2, :m], wk[3, :m], wk[4, :m], wk[5, :m], sc_ahead.copy())
                else:
                    state = cg_start(op, ws, idx, b, Fc, Ax0, has_u_guess, wk[2:])
                bnorm = state[4][2]
                stats[S_SOLVES] += 1
                used = 0
                stops = 0
                u_fresh = False
                if loose_ok and stats[S_ROUNDS] + 1 < max_rounds:
                    for lev in round_tols:
                        if lev <= tol:
                            break
                        if ahead:
                            # the first level's iterations were begun beside the last field;
                            # stopped when the field was done, they go on here (the same
                            # Krylov sequence: cg_run resumes)
                            it, conv, res = int(cg_out[0]), cg_out[1] > 0.0, cg_out[2]
                            if cg_out[3] > 0.0:
                                more, conv, res = cg_run(op, pre, ws, state, idx, Fc, lev, max_iter - it)
                                it += more
                            ahead = False
                        else:
                            it, conv, res = cg_run(op, pre, ws, state, idx, Fc, lev, max_iter - used)
                        used += it
                        if not conv or res <= tol:
                            break          # the tol-solve below reports a failure
                        stops += 1
                        u_fresh = False
                        # distance to a tol-solve in F and in u (the 1e-12 covers CG's
                        # recursive-residual drift), widened by what it can move the slack itself
                        dist = (res + tol + 1e-12) * bnorm * (1.0 + slack * tol) * (1.0 + 1e-9)
                        e = bound_f * dist
                        eu = bound_u * dist
                        n_over, unsure, wo = _snap_check(idx, Fc, f_th, slack * tol, e, marks)
                        n_into = 0
                        if unsure > 0:
                            continue
                        if n_over == 0 and stats[S_ROUNDS] > 0:
                            # no snap after a change this step: nearly always the step's last
                            # round (standard curve at 1/256: all 285), whose tol-solve needs its
                            # own field, so a field here would be computed twice; an entry is found
                            # at tol instead (the same springs, the bound says)
                            break
                        if n_over == 0 and lev > field_level:
                            # entries alone decide this round, and a field this loose leaves
                            # most of them in doubt (1/256: 179 of 297 at 1e-5): wait
                            continue
                        F[:] = 0.0
                        F[idx] = Fc
                        nxt = 1 - cur
                        wn = work[nxt]
                        m2 = 0
                        from_guess = False
                        entries = guess_entries and has_u_guess and stats[S_ROUNDS] == 0
                        if (overlap and not (has_u_guess and used == 0) and stats[S_ROUNDS] + 2 < max_rounds
                                and round_tols[0] > tol
                                and _likely_changes(contact, marks, x0, u_guess, d, slack * tol,
                                                    entries, pred) > 0):
                            # the next round's set as predicted: the certain snaps, and in a
                            # step's first round the entries that its guess's field makes
                            from_guess = has_u_guess and stats[S_ROUNDS] == 0 and n_over == 0
                            m2 = _next_set(contact, pred, guess if from_guess else F, x0, d, iwork[nxt],
                                           wn[0], wn[1]).size
                            if from_guess:
                                for k in range(m2):
                                    wn[2, k] = u_guess[iwork[nxt][k]]
                        if has_u_guess and used == 0:
                            u[:] = u_guess     # the guess itself met the level
                        elif m2 > 0:
                            # the next round's solve beside the field that checks the prediction
                            # (right in 601 of 608 snapping rounds and 70 % of the loading
                            # steps' first rounds at 1/256)
                            idx2 = iwork[nxt][:m2]
                            field_beside_solve(op, op1, pre1, idx, Fc, u, d, contact, F, x0, f_th,
                                               slack * tol, e, eu, marks, pred, idx2, wn[0, :m2],
                                               wn[1, :m2], wn[2, :m2], from_guess, wn[2:], sc_ahead,
                                               round_tols[0], max_iter, counts, cg_out, stop)
                            n_over, n_into, unsure, wo, wi = (counts[0], counts[1], counts[2], counts[3],
                                                              counts[4])
                            ahead = counts[5] > 0
                            stats[S_AHEAD] += ahead
                            stats[S_DROPPED] += not ahead
                            if entries:
                                stats[S_GUESS_KEPT] += ahead
                                stats[S_GUESS_DROPPED] += not ahead
                            if not ahead:
                                ws = cg_workspace(op, pre, idx)    # the solve beside used its buffers
                            u_fresh = True
                            if unsure == 0:
                                decided = n_over > 0 or n_into > 0
                                sc_m = m2
                                break
                            continue
                        else:
                            field(op, ws[0], idx, Fc, u)
                        u_fresh = True
                        n_over, n_into, unsure, wo, wi = _classify(d, idx, contact, F, u, x0, f_th,
                                                                   slack * tol, e, eu, marks)
                        if unsure == 0:
                            # certain: take the decisions, or, if none, end the step at tol
                            decided = n_over > 0 or n_into > 0
                            break
                if not decided:
                    it, conv, res = cg_run(op, pre, ws, state, idx, Fc, tol, max_iter - used)
                    used += it
                    if stops > 0:
                        stats[S_REFINES] += 1
                    if not conv:
                        stats[S_FAILURES] += 1
                    fstats[F_MAX_RES] = max(fstats[F_MAX_RES], res)
                    F[:] = 0.0
                    F[idx] = Fc
                    if has_u_guess and used == 0:
                        # an accepted guess needs no new field: u = C guess is already known
                        u[:] = u_guess
                    elif not (u_fresh and it == 0):
                        field(op, ws[0], idx, Fc, u)
                fstats[F_LAST_RES] = res
                fstats[F_LAST_BNORM] = bnorm
                stats[S_ITERS] += used
                stats[S_LAST_ITERS] = used
        first = False
        stats[S_ROUNDS] += 1
        if not decided:
            n_over, n_into, unsure, wo, wi = _classify(d, idx, contact, F, u, x0, f_th, slack * tol,
                                                       -1.0, -1.0, marks)
        if n_over == 0 and n_into == 0:
            break
        if stats[S_ROUNDS] >= max_rounds:
            stats[S_EXCEEDED] += 1
            break
        # After a first round that only brings springs in, the next starts from the step's
        # own guess (0 on the new springs, its field u_guess known): as few iterations to
        # tol as from this round's F (7 at 1/256), without an application to start, and
        # computable before this round ends. Otherwise from F, the snapped springs at 0.
        has_u_guess = has_u_guess and stats[S_ROUNDS] == 1 and n_over == 0 and not single
        if not has_u_guess:
            guess[:] = F
        if ahead:
            cur = 1 - cur                  # the next round's set and solve are in the other set
        if single:
            # the 'single' rule: change only the worst violator (a snap before an entry)
            if n_over > 0:
                contact[wo] = False
                guess[wo] = 0.0
                stats[S_SNAPPED] += 1
            else:
                contact[wi] = True
                stats[S_ENTERED] += 1
            continue
        for i in range(N):
            if marks[i] == 1:
                contact[i] = False
                guess[i] = 0.0
            elif marks[i] == 2:
                contact[i] = True
        stats[S_SNAPPED] += n_over
        stats[S_ENTERED] += n_into
    if prepare_tol > 0.0 and stats[S_SNAPPED] == 0 and stats[S_ENTERED] == 0:
        prepare_predictions(d, contact, F, u, x0, op, pre, prepare_tol, max_iter, slope, has_slope,
                            base, unit, work[0], iwork[0], stats, fstats)


@njit(**NUMBA_OPTS)
def prepare_predictions(d, contact, F, u, x0, op, pre, tol, max_iter, slope, has_slope, base, unit,
                        wk, iw, stats, fstats):
    """The base and the unit response of the contact set, to ``tol``: F and u at d solved
    again from F (the base: base[0], base[1], and into F and u), and x with C_SS x = 1 on
    the set (unit[0], 0 off it; warm-started from ``slope`` if has_slope) with its field
    w = C x (unit[1]). F(d') = F + (d' - d) x while the set holds. Residuals: ||b - C_SS F||
    (fstats[F_BASE_RES]) and ||1 - C_SS x|| (F_UNIT_RES); two solves and their iterations
    counted in stats (S_UNIT_ITERS: the unit response's). The base replaces the step's F,
    so a base solve that does not converge counts as a failure (S_FAILURES, and its relative
    residual in F_MAX_RES), as a tol-solve's would; the unit response's residual is checked
    by every prediction made from it (tfm.solver.ContactState._predict)."""
    idx = contact_indices(contact, iw)
    m = idx.size
    it = it2 = 0
    res = res2 = 0.0
    unit[0][:] = 0.0
    if m == 0:
        unit[1][:] = 0.0
    else:
        b, x, Ax0 = wk[0, :m], wk[1, :m], wk[2, :m]
        for k in range(m):
            b[k] = d - x0[idx[k]]
            x[k] = F[idx[k]]
            Ax0[k] = u[idx[k]]
        # the calls and array types of snap_rounds' own solves, whose compiled code they
        # share (solve_on_set here, with its own vectors, cost the first run 11 s more
        # compilation: 62 s against 51 s, 2026-11-29)
        ws = cg_workspace(op, pre, idx)
        it, conv, r = cg_run(op, pre, ws, cg_start(op, ws, idx, b, x, Ax0, True, wk[2:]), idx, x, tol,
                             max_iter)
        if not conv:
            stats[S_FAILURES] += 1
            fstats[F_MAX_RES] = max(fstats[F_MAX_RES], r)
        field(op, ws[0], idx, x, u)
        for k in range(m):
            F[idx[k]] = x[k]
        res = r * np.sqrt(blocked_dot(b, b))
        ones, xs = wk[0, :m], wk[1, :m]
        ones[:] = 1.0
        for k in range(m):
            xs[k] = slope[idx[k]] if has_slope else 0.0
        it2, conv2, r2 = cg_run(op, pre, ws, cg_start(op, ws, idx, ones, xs, ones, False, wk[2:]), idx, xs,
                                tol, max_iter)
        field(op, ws[0], idx, xs, unit[1])
        for k in range(m):
            unit[0][idx[k]] = xs[k]
        res2 = r2 * np.sqrt(m)
    base[0][:] = F
    base[1][:] = u
    fstats[F_BASE_RES] = res
    fstats[F_UNIT_RES] = res2
    stats[S_ITERS] += it + it2
    stats[S_UNIT_ITERS] = it2
    stats[S_SOLVES] += 2
    stats[S_PREPARED] = 1
