"""The contact solve and the snapping loop of the paper's Algorithm 1 (Sec. 2.1).

Governing equations (paper, Eq. 1): u = C F, F_i <= F_th,i, x0_i + u_i <= d, with F > 0
tension. For a fixed contact set I_c, u_i = d - x0_i on I_c and F = 0 elsewhere, so the
forces solve C[I_c, I_c] F = d - x0[I_c]: a symmetric positive-definite system, solved by
preconditioned conjugate gradients on the matrix-free operator.

The solver knows nothing about files; it returns arrays and flags.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .config import DECISION_SLACK
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
    edge_steps: int = 0
    unload_complete: bool = True
    wall_time: float = 0.0


class ContactState:
    """Contact set, forces and displacements, advanced one dilatation step at a time."""

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
        self.u = u_guess if (u_guess is not None and stats.iters == 0) else op.apply(idx, Fc)
        return stats

    def unit_response(self) -> np.ndarray:
        """dF/dd on the current contact set: the solution of C_SS x = 1 on the set S,
        zero elsewhere. F is linear in d while the set is fixed, so F(d') = F(d) + (d' - d) x."""
        prob = self.prob
        x = np.zeros_like(self.F)
        idx = np.flatnonzero(self.contact)
        if idx.size == 0:
            return x
        precond = None if prob.precond is None else (lambda r: prob.precond(idx, r))
        xc, _ = pcg(lambda v: prob.operator.apply(idx, v, idx), np.ones(idx.size), np.zeros(idx.size),
                    precond, prob.tol, prob.max_iter)
        x[idx] = xc
        return x

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


def run_protocol(prob: Problem, delta_max: float, step: float, max_unload_steps: int,
                 progress=None) -> CurveResult:
    """Load from d = 0 to d = -delta_max in steps of `step`, then unload until no spring
    is in contact (or max_unload_steps is reached, which is flagged)."""
    out = CurveResult()
    t0 = time.perf_counter()
    state = ContactState(prob)
    n_load = int(np.ceil(delta_max / step - 1e-9))
    k = 0
    for j in range(1, n_load + 1):
        d = -min(j * step, delta_max)
        out.steps.append(state.advance(d, k, "load", out))
        k += 1
    out.unload_complete = False
    for j in range(1, max_unload_steps + 1):
        d = -delta_max + j * step
        rec = state.advance(d, k, "unload", out)
        out.steps.append(rec)
        k += 1
        if progress is not None:
            progress(rec)
        if rec.n_contact == 0:
            out.unload_complete = True
            break
    out.wall_time = time.perf_counter() - t0
    return out
