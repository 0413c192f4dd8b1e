"""The contact solve and the snapping loop of the paper's Algorithm 1 (Sec. 2.1).

Governing equations (paper, Eq. 1): u = C F, F_i <= F_th,i, x0_i + u_i <= d, with F > 0
tension. For a fixed contact set I_c, u_i = d - x0_i on I_c and F = 0 elsewhere, so the
forces solve C[I_c, I_c] F = d - x0[I_c]: a symmetric positive-definite system, solved by
preconditioned conjugate gradients on the matrix-free operator.

The solver knows nothing about files; it returns arrays and flags.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import DECISION_SLACK, ROUND_TOLS
from .kernels.contact import (F_LAST_BNORM, F_LAST_RES, F_MAX_RES, N_STATS, PRE_DIAGONAL, PRE_FFT,
                              PRE_NONE, PRE_STENCIL, S_ENTERED, S_EXCEEDED, S_FAILURES, S_ITERS,
                              S_REFINES, S_ROUNDS, S_SNAPPED, S_SOLVES, field_from_set, snap_rounds,
                              solve_on_set)
from .kernels.fft import fast_len
from .kernels.grid import blocked_dot


@dataclass
class SolveStats:
    iters: int
    converged: bool
    residual: float


def pcg(apply_A, b, x0, precond, tol, max_iter, Ax0=None) -> tuple[np.ndarray, SolveStats]:
    """Preconditioned CG for A x = b, stopping at ||b - A x|| <= tol ||b||.

    ``Ax0``, if known, saves the first operator application. Dot products are summed in
    fixed blocks, so the iterates do not depend on the number of threads."""
    bnorm = np.sqrt(blocked_dot(b, b))
    if bnorm == 0.0:
        return np.zeros_like(b), SolveStats(0, True, 0.0)
    x = x0.copy()
    if Ax0 is not None:
        r = b - Ax0
    else:
        r = b - apply_A(x) if np.any(x) else b.copy()
    rnorm = np.sqrt(blocked_dot(r, r))
    if rnorm <= tol * bnorm:
        return x, SolveStats(0, True, rnorm / bnorm)
    z = precond(r) if precond is not None else r
    p = z.copy()
    rz = blocked_dot(r, z)
    for it in range(1, max_iter + 1):
        Ap = apply_A(p)
        pAp = blocked_dot(p, Ap)
        if pAp <= 0.0:
            # only possible if C is not positive definite on this set (checked upstream)
            return x, SolveStats(it, False, rnorm / bnorm)
        step = rz / pAp
        x += step * p
        r -= step * Ap
        rnorm = np.sqrt(blocked_dot(r, r))
        if rnorm <= tol * bnorm:
            return x, SolveStats(it, True, rnorm / bnorm)
        z = precond(r) if precond is not None else r
        rz_new = blocked_dot(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, SolveStats(max_iter, False, rnorm / bnorm)


@dataclass
class Problem:
    """Everything Algorithm 1 needs, as arrays (built by tfm.simulate)."""

    x0: np.ndarray          # undeformed heights
    f_th: np.ndarray        # threshold force per spring
    area: np.ndarray        # tributary area per spring
    edge: np.ndarray        # springs on the outer ring of the region
    operator: object        # .apply(src, f_src, tgt=None)
    precond: object | None  # (idx, r) -> z
    tol: float
    max_iter: int
    max_rounds: int
    snap_rule: str          # "batch" (paper) or "single"
    skip_solves: bool = False  # predict F on an unchanged set (bench: no gain at 1/128)
    round_tols: tuple = ROUND_TOLS  # decision levels of the rounds (compiled path; (): off)


@dataclass
class StepRecord:
    step: int
    phase: str
    d: float
    force: float
    contact_area: float
    n_contact: int
    n_snapped: int
    n_entered: int
    rounds: int
    solver_iters: int


@dataclass
class CurveResult:
    steps: list = field(default_factory=list)
    n_solves: int = 0
    solver_iters: int = 0
    max_residual: float = 0.0
    solver_failures: int = 0
    rounds_exceeded: int = 0
    refines: int = 0             # loose decision solves carried on to tol (compiled path)
    edge_steps: int = 0
    unload_complete: bool = True
    wall_time: float = 0.0


class ContactState:
    """Contact set, forces and displacements, advanced one dilatation step at a time.

    ``F``, ``u`` and ``contact`` are full-grid NumPy arrays, valid after each advance. On
    the square grid with the FFT operator the rounds of a step run compiled
    (tfm.kernels.contact: no return to Python per CG iteration or per round); other
    operators (direct, tree) run the same algorithm in Python around their compiled sums."""

    def __init__(self, prob: Problem):
        self.prob = prob
        n = prob.x0.size
        self.contact = np.zeros(n, dtype=bool)
        self.F = np.zeros(n)
        self.u = np.zeros(n)
        # dF/dd and du/dd from the last two converged steps (warm start)
        self._slope = None
        self._uslope = None
        self._last_d = None
        # skip-the-solve state: a solution on the current set (base) and the set's unit
        # response; _set_id counts contact-set changes
        self.skip_solves = prob.skip_solves
        self._set_id = 0
        self._base = None
        self._unit = None
        self._unit_set = -1
        op = prob.operator
        self._compiled = getattr(op, "name", "") == "fft" and hasattr(op, "syms")
        if self._compiled:
            self._setup_compiled()

    # ------------------------------------------------------------------ compiled path
    def _setup_compiled(self):
        prob, op = self.prob, self.prob.operator
        n = op.n
        P = fast_len(2 * n - 1)
        self._sym_full = op.symbols(P)[0]
        # Bounds for the loose decision rounds (snap_rounds): every C_SS is a principal
        # submatrix of the P-periodic circulant whose eigenvalues are the symbol, so its
        # smallest eigenvalue is at least min(symbol), and each row of C is part of a row
        # of the circulant, whose 2-norm is that of the kernel on the periodic box.
        self._lam_lo = float(self._sym_full.min())
        self._row_norm = float(np.sqrt(np.sum(np.fft.irfft2(self._sym_full, s=(P, P)) ** 2)))
        # work buffers of the whole-grid field u = C F (reused every solve)
        self._src = np.zeros((n, n))
        self._spec = np.zeros((n, P // 2 + 1), dtype=np.complex128)
        self._out = np.empty((n, P))
        # threads only where they pay on this machine now (same bits either way)
        self.threaded = op.threaded()
        pre = prob.precond
        name = getattr(pre, "name", "none") if pre is not None else "none"
        self._pre = {"none": PRE_NONE, "diagonal": PRE_DIAGONAL, "fft": PRE_FFT,
                     "stencil": PRE_STENCIL}[name]
        self._stencil = getattr(pre, "stencil", np.zeros((1, 1)))
        self._x0 = np.ascontiguousarray(prob.x0, dtype=float)
        self._f_th = np.ascontiguousarray(prob.f_th, dtype=float)

    def _rounds_compiled(self, d, guess, u_guess, out, solved=False):
        prob, op = self.prob, self.prob.operator
        stats = np.zeros(N_STATS, dtype=np.int64)
        fstats = np.array([out.max_residual, 0.0, 0.0])
        guess = np.array(guess, dtype=float)             # overwritten by the rounds
        ug = self.u if u_guess is None else np.ascontiguousarray(u_guess)
        snap_rounds(float(d), self.contact, self.F, self.u, guess, ug, u_guess is not None, solved,
                    self._x0, self._f_th, op.n, op.spacing, op.cut2, op.diag, op.syms, op.isyms,
                    self._pre, self._stencil, self._sym_full, self._src, self._spec, self._out,
                    prob.tol, prob.max_iter, prob.max_rounds, prob.snap_rule == "single",
                    DECISION_SLACK, np.array(prob.round_tols, dtype=float), self._lam_lo, self._row_norm, stats, fstats,
                    self.threaded)
        out.max_residual = float(fstats[F_MAX_RES])
        out.n_solves += int(stats[S_SOLVES])
        out.solver_failures += int(stats[S_FAILURES])
        out.rounds_exceeded += int(stats[S_EXCEEDED])
        out.refines += int(stats[S_REFINES])
        if stats[S_SOLVES] > 0:
            # the step ended on a real solve: the base of later predictions on this set
            self._base = (self.F.copy(), self.u.copy(), float(d),
                          float(fstats[F_LAST_RES] * fstats[F_LAST_BNORM]))
        return (int(stats[S_ROUNDS]), int(stats[S_ITERS]), int(stats[S_SNAPPED]),
                int(stats[S_ENTERED]))

    def _solve_unit(self):
        """x with C_SS x = 1 on the contact set (0 off it), its field w = C x on the grid,
        and ||1 - C_SS x||; warm-started from the last step's dF/dd."""
        prob, op = self.prob, self.prob.operator
        idx = np.flatnonzero(self.contact)
        x, w = np.zeros(self.F.size), np.zeros(self.F.size)
        if idx.size == 0:
            return x, w, 0.0, 0
        ones = np.ones(idx.size)
        xs = self._slope[idx].copy() if self._slope is not None else np.zeros(idx.size)
        it, conv, res = solve_on_set(idx, ones, xs, ones, False, op.n, op.spacing, op.cut2, op.diag,
                                     op.syms, op.isyms, self._pre, self._stencil, prob.tol,
                                     prob.max_iter, self.threaded)
        x[idx] = xs
        field_from_set(idx, xs, op.n, self._sym_full, self._src, self._spec, self._out, w,
                       self.threaded)
        return x, w, res * np.sqrt(idx.size), it

    def unit_response(self, out: CurveResult | None = None) -> np.ndarray:
        """dF/dd on the current contact set: the full-grid solution of C_SS x = 1 on the
        set, zero off it (F is linear in d while the set is fixed: F(d) = F(d0) + (d - d0) x).
        A new solve is counted in ``out`` (n_solves, solver_iters) when given."""
        if self._unit is None or self._unit_set != self._set_id:
            if self._compiled:
                self._unit = self._solve_unit()
            else:
                self._unit = self._unit_python()
            self._unit_set = self._set_id
            if out is not None and self.contact.any():
                out.n_solves += 1
                out.solver_iters += self._unit[3]
        return self._unit[0].copy()

    def _unit_python(self):
        """As _solve_unit, on the Python path (the field is not needed there)."""
        prob, op = self.prob, self.prob.operator
        idx = np.flatnonzero(self.contact)
        x = np.zeros(self.F.size)
        iters = 0
        if idx.size:
            precond = None if prob.precond is None else (lambda r: prob.precond(idx, r))
            x[idx], stats = pcg(lambda v: op.apply(idx, v, idx), np.ones(idx.size), np.zeros(idx.size),
                                precond, prob.tol, prob.max_iter)
            iters = stats.iters
        return x, None, None, iters

    def _predict(self, d):
        """F and u at d from the base solution and the unit response of the unchanged set,
        if the residual bound ||r_base|| + |d - d_base| ||r_x|| stays within tol ||b||."""
        if self._base is None or self._unit is None or self._unit_set != self._set_id:
            return False
        Fb, ub, db, rb = self._base
        x, w, rx, _ = self._unit
        c = d - db
        idx = np.flatnonzero(self.contact)
        bnorm = float(np.sqrt(blocked_dot(d - self.prob.x0[idx], d - self.prob.x0[idx])))
        if rb + abs(c) * rx > self.prob.tol * bnorm:
            return False
        np.add(Fb, c * x, out=self.F)
        np.add(ub, c * w, out=self.u)
        return True

    # ------------------------------------------------------------------ Python path
    def _solve(self, d, guess, u_guess=None):
        """Solve on the current contact set; ``u_guess`` = C @ guess when known exactly."""
        prob = self.prob
        idx = np.flatnonzero(self.contact)
        if idx.size == 0:
            self.F[:] = 0.0
            self.u[:] = 0.0
            return SolveStats(0, True, 0.0)
        op = prob.operator
        b = d - prob.x0[idx]
        precond = None if prob.precond is None else (lambda r: prob.precond(idx, r))
        Ax0 = None if u_guess is None else u_guess[idx]
        Fc, stats = pcg(lambda v: op.apply(idx, v, idx), b, guess[idx], precond, prob.tol,
                        prob.max_iter, Ax0=Ax0)
        self.F[:] = 0.0
        self.F[idx] = Fc
        # an accepted guess needs no new field: u = C @ guess is already known
        self.u[:] = u_guess if (u_guess is not None and stats.iters == 0) else op.apply(idx, Fc)
        return stats

    def _rounds_python(self, d, guess, u_guess, out):
        prob = self.prob
        rounds = iters = snapped = entered = 0
        while True:
            stats = self._solve(d, guess, u_guess)
            u_guess = None
            out.n_solves += 1 if self.contact.any() else 0
            iters += stats.iters
            out.max_residual = max(out.max_residual, stats.residual)
            if not stats.converged:
                out.solver_failures += 1
            rounds += 1
            # Decisions ignore violations at the level of the solve's own error.
            scale_f = float(np.abs(self.F).max()) if self.contact.any() else 0.0
            slack_f = DECISION_SLACK * prob.tol * scale_f
            slack_u = DECISION_SLACK * prob.tol * max(abs(d), float(np.abs(self.u).max()))
            over = self.contact & (self.F > prob.f_th + slack_f)
            into = ~self.contact & (prob.x0 + self.u > d + slack_u)
            if not over.any() and not into.any():
                break
            if rounds >= prob.max_rounds:
                out.rounds_exceeded += 1
                break
            if prob.snap_rule == "single":
                over, into = _worst_only(over, into, self.F - prob.f_th, prob.x0 + self.u - d)
            self.contact[over] = False
            self.contact[into] = True
            snapped += int(over.sum())
            entered += int(into.sum())
            guess = self.F.copy()
            guess[over] = 0.0
        return rounds, iters, snapped, entered

    # ------------------------------------------------------------------ one step
    def advance(self, d: float, k: int, phase: str, out: CurveResult) -> StepRecord:
        prob = self.prob
        guess, u_guess = self.F, None
        if self._slope is not None:
            # F and u = C F are both linear in d: C (F + c dF) = u + c du. The known field
            # is the guess's own only if the guess vanishes off the contact set, i.e. no
            # spring snapped in the last step (a snapped spring's dF is -F/dd).
            c = d - self._last_d
            guess = self.F + c * self._slope
            if not self._slope[~self.contact].any():
                u_guess = self.u + c * self._uslope
        start_F, start_u = self.F.copy(), self.u.copy()
        if self._compiled:
            # Skip the solve while the set is unchanged: F = F_base + (d - d_base) x.
            solved = self.skip_solves and self._predict(d)
            rounds, iters, snapped, entered = self._rounds_compiled(d, guess, u_guess, out, solved)
        else:
            rounds, iters, snapped, entered = self._rounds_python(d, guess, u_guess, out)
        if snapped or entered:
            self._set_id += 1
        elif self.skip_solves and self._compiled and (self._unit is None or self._unit_set != self._set_id):
            # the set survived a whole step: its unit response will likely serve the next ones
            self._unit = self._solve_unit()
            self._unit_set = self._set_id
            iters += self._unit[3]
            out.n_solves += 1
        # dF/dd for the next step's warm start. Exact while the contact set is unchanged
        # (F is linear in d for a fixed set); still a good guess after small changes.
        if self._last_d is not None and d != self._last_d:
            self._slope = (self.F - start_F) / (d - self._last_d)
            self._uslope = (self.u - start_u) / (d - self._last_d)
        else:
            self._slope = self._uslope = None
        self._last_d = d
        if (self.contact & prob.edge).any():
            out.edge_steps += 1
        out.solver_iters += iters
        return StepRecord(k, phase, d, -float(self.F.sum()), float(prob.area[self.contact].sum()),
                          int(self.contact.sum()), snapped, entered, rounds, iters)


def _worst_only(over, into, excess_f, excess_u):
    """The 'single' rule: change only the worst violator (a snap before an entry)."""
    o = np.zeros_like(over)
    i = np.zeros_like(into)
    if over.any():
        cand = np.flatnonzero(over)
        o[cand[np.argmax(excess_f[cand])]] = True
    else:
        cand = np.flatnonzero(into)
        i[cand[np.argmax(excess_u[cand])]] = True
    return o, i
