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
from numba import njit

from ..config import NUMBA_OPTS
from .grid import blocked_dot
from .ops import apply_set, field, precondition, restrict, restrict_pre

# slots of the integer statistics array
(S_SOLVES, S_ITERS, S_FAILURES, S_ROUNDS, S_SNAPPED, S_ENTERED, S_EXCEEDED, S_LAST_ITERS,
 S_REFINES) = range(9)
N_STATS = 9
# slots of the float statistics array
F_MAX_RES, F_LAST_RES, F_LAST_BNORM = range(3)


@njit(**NUMBA_OPTS)
def cg_workspace(op, pre, idx):
    """The operator and the preconditioner restricted to the contact set idx, built once
    per solve (tfm.kernels.ops.restrict, restrict_pre)."""
    return restrict(op, idx), restrict_pre(pre, idx)


@njit(**NUMBA_OPTS)
def cg_start(op, ws, idx, b, x, Ax0, has_Ax0):
    """CG state for C_SS x = b from the guess x: (r, z, p, Ap, sc) with sc = [r.z, ||r||,
    ||b||, phase]; phase 0: not started, 1: p is the next direction, 2: r was updated last
    and z, p still have to follow. ``Ax0`` = C x when has_Ax0 saves the first application."""
    m = idx.size
    Ap = np.empty(m)
    if has_Ax0:
        r = b - Ax0
    else:
        nonzero = False
        for k in range(m):
            if x[k] != 0.0:
                nonzero = True
                break
        if nonzero:
            apply_set(op, ws[0], idx, x, Ap)
            r = b - Ap
        else:
            r = b.copy()
    sc = np.array([0.0, np.sqrt(blocked_dot(r, r)), np.sqrt(blocked_dot(b, b)), 0.0])
    return r, np.empty(m), np.empty(m), Ap, sc


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
def cg_run(op, pre, ws, state, idx, x, tol, max_iter):
    """Carry PCG on from ``state`` until ||r|| <= tol ||b|| or max_iter iterations in this
    call. A later call with a smaller tol continues the same Krylov sequence (no restart),
    so a solve stopped early for a decision loses nothing when it must go on. Returns
    (iterations, converged, relative residual)."""
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
        sc[0] = _next_direction(pre, ws, r, z, p, sc[0], idx)
    return max_iter, False, sc[1] / bnorm


@njit(**NUMBA_OPTS)
def solve_on_set(op, pre, idx, b, x, Ax0, has_Ax0, tol, max_iter, u, with_field):
    """PCG for C_SS x = b on the contact set idx (sorted flat indices), from the guess x
    (overwritten), stopping at ||b - C x|| <= tol ||b||. ``Ax0`` = C x when has_Ax0 saves
    the first application. With with_field, u (one entry per spring) receives the field
    C x (x on idx, 0 elsewhere). Returns (iterations, converged, relative residual)."""
    ws = cg_workspace(op, pre, idx)
    state = cg_start(op, ws, idx, b, x, Ax0, has_Ax0)
    res = cg_run(op, pre, ws, state, idx, x, tol, max_iter)
    if with_field:
        field(op, ws[0], idx, x, u)
    return res


@njit(**NUMBA_OPTS)
def _slacks(d, contact, F, u, rel, with_u):
    """Decisions ignore violations at the level of the solve's own error: rel times the
    largest contact force, and rel times the largest of |d| and |u| (|d| alone if not
    with_u: u is not current)."""
    scale_f = 0.0
    scale_u = abs(d)
    for i in range(contact.size):
        if contact[i]:
            scale_f = max(scale_f, abs(F[i]))
        if with_u:
            scale_u = max(scale_u, abs(u[i]))
    return rel * scale_f, rel * scale_u


@njit(**NUMBA_OPTS)
def _classify(d, contact, F, u, x0, f_th, slack_f, slack_u, bf, bu, marks, entries):
    """marks[i] = 1 if spring i snaps, 2 if it enters, 0 if it stays (Algorithm 1's rules,
    violations below the slack ignored). With bounds bf, bu > 0 on the distance to the
    tolerance-tol solution (forces, displacements), also counts the springs whose fate that
    distance could change. ``entries`` False: the contact springs only (u not needed).
    Returns (snapping, entering, unsure, worst snap, worst entry)."""
    n_over = 0
    n_into = 0
    unsure = 0
    worst_over = -1
    worst_into = -1
    for i in range(contact.size):
        marks[i] = 0
        if contact[i]:
            g = F[i] - (f_th[i] + slack_f)
            if g > 0.0:
                marks[i] = 1
                n_over += 1
                if worst_over < 0 or F[i] - f_th[i] > F[worst_over] - f_th[worst_over]:
                    worst_over = i
            if abs(g) <= bf:
                unsure += 1
        elif entries:
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
def snap_rounds(d, contact, F, u, guess, u_guess, has_u_guess, solved, x0, f_th, op, pre, tol,
                max_iter, max_rounds, single, slack, round_tols, lam_lo, row_norm, stats, fstats):
    """The rounds of one dilatation step d (Algorithm 1): solve on the contact set, then
    snap every spring above its threshold and bring in every penetrating one (or only the
    worst, ``single``), until nothing changes or max_rounds is reached.

    Decision levels. A round's solve stops at each of the loose relative residuals
    ``round_tols`` (descending, all > tol) in turn and asks whether the decisions are
    already certain: ||F - F_tol|| <= (||r|| + tol ||b||) / lam_lo for any two solutions
    with residuals r and tol ||b|| (lam_lo <= the smallest eigenvalue of every C_SS), and
    |u_i - u_tol,i| <= row_norm times that (row_norm >= every row's 2-norm of C). If no
    spring lies within those bounds of its decision line and some spring changes, the
    round's decisions are taken there; the sequence of contact sets is the one tol-solves
    give. Otherwise CG carries on (same Krylov sequence, no restart) to the next level,
    and finally to tol: the last round of every step is a tol-solve. The snap check needs
    only F, so the field u is computed at a level only once no snap is in doubt. An empty
    round_tols (or lam_lo <= 0) solves every round to tol.

    ``op`` and ``pre`` are the operator's and the preconditioner's data (tfm.kernels.ops).
    contact, F, u are updated in place (one entry per spring). ``guess`` is the first
    solve's guess for F; ``u_guess`` = C guess when has_u_guess. ``solved``: F and u
    already hold the solution on the current set (the first solve is skipped). Counts go
    to ``stats``; ``fstats`` holds the largest relative residual of the tol-solves
    (updated), then the relative residual and ||b|| of the last solve."""
    N = contact.size
    marks = np.zeros(N, dtype=np.int8)
    loose_ok = round_tols.size > 0 and lam_lo > 0.0 and not single
    first = True
    n_over = n_into = unsure = wo = wi = 0
    while True:
        decided = False
        res = 0.0
        idx = np.flatnonzero(contact)
        if not (first and solved):
            if idx.size == 0:
                F[:] = 0.0
                u[:] = 0.0
                stats[S_LAST_ITERS] = 0
                fstats[F_LAST_RES] = 0.0
                fstats[F_LAST_BNORM] = 0.0
            else:
                b = d - x0[idx]
                Fc = guess[idx]
                Ax0 = u_guess[idx] if has_u_guess else b
                ws = cg_workspace(op, pre, idx)
                state = cg_start(op, ws, idx, b, Fc, Ax0, has_u_guess)
                bnorm = state[4][2]
                stats[S_SOLVES] += 1
                used = 0
                stops = 0
                u_fresh = False
                if loose_ok and stats[S_ROUNDS] + 1 < max_rounds:
                    for lev in round_tols:
                        if lev <= tol:
                            break
                        it, conv, res = cg_run(op, pre, ws, state, idx, Fc, lev, max_iter - used)
                        used += it
                        if not conv or res <= tol:
                            break          # the tol-solve below reports a failure
                        stops += 1
                        u_fresh = False
                        F[:] = 0.0
                        F[idx] = Fc
                        # distance to a tol-solve (the 1e-12 covers CG's recursive-residual
                        # drift), widened by what it can move the slack itself
                        e = (res + tol + 1e-12) * bnorm / lam_lo * (1.0 + slack * tol) * (1.0 + 1e-9)
                        slack_f, slack_u = _slacks(d, contact, F, u, slack * tol, False)
                        n_over, n_into, unsure, wo, wi = _classify(d, contact, F, u, x0, f_th, slack_f,
                                                                   slack_u, e, row_norm * e, marks, False)
                        if unsure > 0:
                            continue
                        if has_u_guess and used == 0:
                            u[:] = u_guess     # the guess itself met the level
                        else:
                            field(op, ws[0], idx, Fc, u)
                        u_fresh = True
                        slack_f, slack_u = _slacks(d, contact, F, u, slack * tol, True)
                        n_over, n_into, unsure, wo, wi = _classify(d, contact, F, u, x0, f_th, slack_f,
                                                                   slack_u, e, row_norm * e, marks, True)
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
        has_u_guess = False
        stats[S_ROUNDS] += 1
        if not decided:
            slack_f, slack_u = _slacks(d, contact, F, u, slack * tol, True)
            n_over, n_into, unsure, wo, wi = _classify(d, contact, F, u, x0, f_th, slack_f, slack_u,
                                                       -1.0, -1.0, marks, True)
        if n_over == 0 and n_into == 0:
            break
        if stats[S_ROUNDS] >= max_rounds:
            stats[S_EXCEEDED] += 1
            break
        guess[:] = F
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
