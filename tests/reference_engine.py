"""Slow twin of the compiled contact engine: today's (commit bdbd1f4) Python engine, frozen.

The PCG, the snapping rounds of Algorithm 1 and the scipy.fft operator on the contact's
box, exactly as tfm ran them before the compiled engine, one Python call per CG step.
tests/test_engine.py runs it live beside tfm.simulate and compares every step.
Do not optimise this file: its value is that it is the old, obvious code.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from tfm.config import DECISION_SLACK
from tfm.geometry import heights, make_layout
from tfm.kernels.grid import blocked_dot
from tfm.operators import kernel_spec
from tfm.params import ParameterError
from tfm.threshold import threshold_forces


def fft_workers():
    return 1


def index_box(n, idx):
    i, j = idx // n, idx % n
    return i.min(), j.min(), max(i.max() - i.min(), j.max() - j.min()) + 1


def scatter_box(buf, n, i0, j0, idx, vals):
    buf[idx // n - i0, idx % n - j0] = vals


def gather_box(box, n, i0, j0, idx):
    return box[idx // n - i0, idx % n - j0]


def _grid_kernel(spec: KernelSpec, n: int, P: int, spacing: float, diag0: float) -> np.ndarray:
    """The kernel on a P x P periodic box, holding every offset |a|, |b| <= n - 1.

    With P >= 2n - 1 the circular convolution of a zero-padded n x n field equals the
    linear one: no periodic images."""
    a = np.arange(P)
    a = np.where(a < n, a, np.where(a > P - n, a - P, 0)).astype(float)
    keep = (np.arange(P) < n) | (np.arange(P) > P - n)
    r = np.hypot(a[:, None], a[None, :]) * spacing
    K = spec.offdiag(r) * (keep[:, None] & keep[None, :])
    K[0, 0] = diag0
    return K


def box_symbol(spec: KernelSpec, P: int, spacing: float) -> np.ndarray:
    """Real symbol of the kernel on a P x P periodic box: exact linear convolution for any
    sources and targets within a (P + 1) // 2 wide box."""
    K = _grid_kernel(spec, (P + 1) // 2, P, spacing, float(spec.diag[0]))
    # the kernel is real and even, so its transform is real up to round-off
    return sfft.rfft2(K).real.copy()


def grid_symbol(spec: KernelSpec, layout: Layout) -> tuple[np.ndarray, int]:
    """Symbol of the circulant embedding of C on the whole square grid, and its size P."""
    n = layout.shape[0]
    P = sfft.next_fast_len(2 * n - 1, real=True)
    return box_symbol(spec, P, layout.spacing), P


class FFTOperator:
    """Exact zero-padded convolution on the square grid (scipy.fft, fast sizes).

    The convolution runs on the bounding box (width w) of the sources and targets only,
    padded to a fast size P >= 2w - 1: inside the contact solve both are the contact set,
    far smaller than the grid. The transform is pruned: only the w non-zero rows are
    transformed along the rows, and only the w wanted rows are transformed back.
    Symbols are cached per P. Small transforms run on one thread (bench: thread start-up
    costs more than it saves below P ~ 512); pocketfft computes every 1-D transform the
    same way for any thread count, so results do not depend on it."""

    name = "fft"
    THREADED_SIZE = 512

    def __init__(self, spec: KernelSpec, layout: Layout, symbol=None):
        if layout.shape is None:
            raise ParameterError("operator: 'fft' needs a regular square grid")
        self.spec, self.spacing = spec, layout.spacing
        self.n = layout.shape[0]
        self.all = np.arange(layout.n)
        self.workers = fft_workers()
        self._symbols: dict[int, np.ndarray] = {}
        self._inverses: dict[int, np.ndarray] = {}
        if symbol is not None:
            self._symbols[symbol[1]] = symbol[0]

    def symbol(self, P: int) -> np.ndarray:
        if P not in self._symbols:
            self._symbols[P] = box_symbol(self.spec, P, self.spacing)
        return self._symbols[P]

    def inverse_symbol(self, P: int) -> np.ndarray:
        if P not in self._inverses:
            self._inverses[P] = 1.0 / self.symbol(P)
        return self._inverses[P]

    def apply_inverse(self, src, f_src, tgt=None):
        """C^-1 on the box of src and tgt (the FFT preconditioner): same transforms."""
        return self._convolve(src, f_src, tgt, self.inverse_symbol)

    def apply(self, src, f_src, tgt=None):
        return self._convolve(src, f_src, tgt, self.symbol)

    def _convolve(self, src, f_src, tgt, symbol_of):
        n = self.n
        if tgt is None:
            i0, j0, w, tgt = 0, 0, n, self.all
        elif tgt is src:
            i0, j0, w = index_box(n, src)
        else:
            i0, j0, w = index_box(n, np.concatenate((src, tgt)))
        w = max(w, 1)
        P = sfft.next_fast_len(2 * w - 1, real=True)
        workers = self.workers if P >= self.THREADED_SIZE else 1
        box = np.zeros((w, w))
        scatter_box(box, n, i0, j0, src, f_src)
        a = sfft.rfft(box, n=P, axis=1, workers=workers)
        a = sfft.fft(a, n=P, axis=0, workers=workers, overwrite_x=True)
        a *= symbol_of(P)
        a = sfft.ifft(a, axis=0, workers=workers, overwrite_x=True)[:w]
        u = sfft.irfft(a, n=P, axis=1, workers=workers)
        return gather_box(u, n, i0, j0, tgt)


class FFTPreconditioner:
    """R C^-1 R^T with the inverse symbol on the contact's box (two FFTs per application)."""

    name = "fft"

    def __init__(self, op: FFTOperator):
        self.op = op            # shares the operator's symbol cache

    def __call__(self, idx, r):
        return self.op.apply_inverse(idx, r, idx)


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


def reference_curve(p):
    """The load-unload curve of Params ``p`` (square grid, FFT operator, FFT preconditioner)
    with the old engine: a list of StepRecord and the CurveResult."""
    layout = make_layout(p)
    spec = kernel_spec(p, layout)
    op = FFTOperator(spec, layout)
    prob = Problem(x0=heights(p, layout), f_th=threshold_forces(p, layout.area), area=layout.area,
                   edge=layout.edge, operator=op, precond=FFTPreconditioner(op), tol=p.tol,
                   max_iter=p.max_iter, max_rounds=p.max_rounds, snap_rule=p.snap_rule)
    n_load = int(np.ceil(p.delta_max / p.step - 1e-9))
    return run_protocol(prob, p.delta_max, p.step, p.max_unload_steps or (20 * n_load + 1000))
