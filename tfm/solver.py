"""The contact solve and the snapping loop of the paper's Algorithm 1 (Sec. 2.1).

Governing equations (paper, Eq. 1): u = C F, F_i <= F_th,i, x0_i + u_i <= d, with F > 0
tension. For a fixed contact set I_c, u_i = d - x0_i on I_c and F = 0 elsewhere, so the
forces solve C[I_c, I_c] F = d - x0[I_c]: a symmetric positive-definite system, solved by
preconditioned conjugate gradients on the matrix-free operator.

The solver knows nothing about files; it returns arrays and flags.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

import numba
import numpy as np

from .config import DECISION_SLACK, FIELD_LEVEL, ROUND_TOLS, RUN_THREADED_SIZE, SKIP_MIN_TOL, SKIP_TOL
from .kernels.contact import (F_BASE_RES, F_LAST_BNORM, F_LAST_RES, F_MAX_RES, F_UNIT_RES, N_FSTATS,
                              N_STATS, S_AHEAD, S_DROPPED, S_ENTERED, S_EXCEEDED, S_FAILURES,
                              S_GUESS_DROPPED, S_GUESS_KEPT, S_ITERS, S_PREPARED, S_REFINES, S_ROUNDS,
                              S_SNAPPED, S_SOLVES, S_UNIT_ITERS, difference_quotients, extrapolate,
                              predicted, rhs_norm, snap_rounds, solve_on_set)
from .kernels.fft import inverse_kernel
from .kernels.ops import PRE_FFT, FFTData
from .operators import pre_data


@dataclass
class Problem:
    """Everything Algorithm 1 needs, as arrays (built by tfm.simulate)."""

    x0: np.ndarray          # undeformed heights
    f_th: np.ndarray        # threshold force per spring
    area: np.ndarray        # tributary area per spring
    edge: np.ndarray        # springs on the outer ring of the region
    operator: object        # .apply(src, f_src, tgt=None), .compiled()
    precond: object | None  # (idx, r) -> z, .compiled()
    tol: float
    max_iter: int
    max_rounds: int
    snap_rule: str          # "batch" (paper) or "single"
    skip_solves: bool = True   # predict F while the set is unchanged (config.SKIP_TOL)
    round_tols: tuple = ROUND_TOLS  # decision levels of the rounds (compiled path; (): off)
    field_level: float = FIELD_LEVEL  # the loosest level with a field where no spring snaps
    threads: str = "auto"   # FFT operator: "serial", "threaded" or chosen step by step (ThreadChoice)


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
    loads_short: int = 0         # force control: load steps whose moves ran out below the target
    refines: int = 0             # loose decision solves carried on to tol (compiled path)
    solves_ahead: int = 0        # solves run beside the previous round's field and kept
    solves_dropped: int = 0      # ... and dropped (an entry in that round, or one in doubt)
    edge_steps: int = 0
    threaded_steps: int = 0      # steps with a solve taken in the threaded mode (ContactState.threaded)
    unload_complete: bool = True
    wall_time: float = 0.0


def entry_point(dispatcher, args):
    """The compiled code of ``dispatcher`` for the types of ``args``, to call once per step:
    a Numba dispatcher types every argument on every call, and for the operator's data
    (NamedTuples holding typed dicts) that took 1.6 ms a call, 12 % of a 1/256 curve. The
    caller must pass arguments of the same types on every call."""
    return dispatcher.compile(tuple(numba.typeof(a) for a in args))


class ThreadChoice:
    """Serial or threaded (the field beside the next round's solve, and transforms split
    from tfm.kernels.fft.THREADED_SIZE), chosen from the run's own steps, again and again.

    The bits do not depend on the choice, only the time. Neither mode wins everywhere on
    the 2-core VM: in its quiet spells the standard 1/256 curve took 1.51-1.52 s threaded
    against 1.76-1.94 s serial, in others (within the same hour, around midnight of
    2026-11-28) 2.27-2.33 s threaded against 1.69-1.80 s serial, when one convolution split
    over two threads took 0.33 ms against 0.19 ms on one. A timing of a few convolutions at
    start proved a poor guide (2026-11-24). So every cycle runs TRIAL steps in each mode,
    alternating, and holds the faster mode for HOLD steps, from the first step on. Faster:
    the median over the trial's pairs of neighbouring steps (threaded, then serial) of
    their ratio of wall time per unit of work (CG iterations + rounds + 1). Neighbours are
    alike, and the median is not moved by one step unlike the rest; the summed times of
    each mode, used before, held threaded in 6 of 9 cycles of a run in which it cost 0.33
    ms a unit of work against 0.19 ms serial (then 1.73-1.75 s, against 2.14 s).

    Only steps with CG iterations count, in the trials and in the hold: a step predicted
    without a solve does the same in both modes, so its ratio is noise. At 1/512 such
    steps filled 4 of the 10 trials, whose coin-toss choices then held through parts of
    the cascade: 13.1-14.8 s against 11.8-13.4 s forced threaded (2026-11-29). For the same
    reason a new phase (loading, unloading) starts a new cycle (``restart``): the last
    loading trial, at 1/512 a near tie, held serial into the cascade."""

    TRIAL = 4
    HOLD = 48

    def __init__(self):
        self.k = 0
        self.mode = True
        self._ratios = []
        self._threaded = None

    def restart(self) -> None:
        """A new trial from the next step on (steps of another kind follow)."""
        self.k = 0
        self._ratios = []
        self._threaded = None

    def next(self) -> bool:
        """The mode of the next step."""
        pos = self.k % (2 * self.TRIAL + self.HOLD)
        if pos < 2 * self.TRIAL:
            return pos % 2 == 0
        if pos == 2 * self.TRIAL:
            if self._ratios:
                self.mode = statistics.median(self._ratios) < 1.0   # threaded if faster
            self._ratios = []
        return self.mode

    def record(self, threaded: bool, seconds: float, iters: int, rounds: int) -> None:
        """The step just taken: its mode, wall time, CG iterations and rounds."""
        if iters == 0:
            return                          # no solve: the modes do the same
        if self.k % (2 * self.TRIAL + self.HOLD) < 2 * self.TRIAL:
            per_unit = seconds / (iters + rounds + 1)
            if threaded:
                self._threaded = per_unit
            elif self._threaded is not None and per_unit > 0.0:
                self._ratios.append(self._threaded / per_unit)
        self.k += 1


class EntryGuess:
    """Whether a step's first round predicts its entries from the field of the step's guess
    (snap_rounds' ``guess_entries``), judged by how such predictions fared in this run.

    The solve run beside the field on the predicted set is kept only if every decision is
    as predicted. The extrapolated field overshoots at the contact's edge, so while loading
    it brings in a few springs too many: exact at 1/256 in 59 % of the loading steps, at
    1/512 in 4 % (40 extra springs on a ring of about 190, 2026-11-29). A dropped solve
    costs the field its second thread; a kept one saves most of a solve. So the guess is
    used while at least RATE of the recent ones held (counts decayed by DECAY per step that
    tried), and tried every PROBE steps otherwise."""

    RATE = 0.25
    DECAY = 0.9
    PROBE = 16

    def __init__(self):
        self.kept = self.dropped = 0.0
        self.k = 0

    def use(self) -> bool:
        self.k += 1
        return (self.kept + 1.0) / (self.kept + self.dropped + 2.0) >= self.RATE or self.k % self.PROBE == 0

    def record(self, kept: int, dropped: int) -> None:
        if kept + dropped:
            self.kept = self.DECAY * self.kept + kept
            self.dropped = self.DECAY * self.dropped + dropped


def decision_bounds(op) -> tuple[float, float]:
    """(bound_f, bound_u) of snap_rounds' loose decision rounds, for the FFT operator's data
    ``op``: how far a force F_k, and a displacement u_i off the contact set, can move per
    unit change of the residual, on any contact set S. Every C_SS is a principal submatrix
    of the P-periodic circulant of the whole grid's box, whose eigenvalues are the symbol:
    its smallest eigenvalue is at least lam = min(symbol). A residual change dr moves F by
    C_SS^-1 dr, so F_k by at most ||row k of C_SS^-1|| ||dr||, and
    ||row k||^2 = (C_SS^-2)_kk <= (C_SS^-1)_kk / lam <= K_0 / lam, with K_0 the inverse
    kernel at offset 0 of the circulant (a principal submatrix has the smaller inverse
    diagonal): bound_f = sqrt(K_0 / lam). It moves u_i = c^T F (c: spring i's couplings to
    S) by at most ||C_SS^-1 c|| ||dr||. In the inverse of C on S and i, column i is
    x (-C_SS^-1 c, 1) with x = 1 / (C_ii - c^T C_SS^-1 c) >= 1 / C_ii, and its squared norm
    is at most x / lam, so ||C_SS^-1 c||^2 <= 1 / (x lam) - 1: bound_u = sqrt(C_ii / lam - 1).
    Against the 2-norm bounds used before, 1 / lam and (row 2-norm of C) / lam, these are
    0.85 and 0.27 times as large at 1/256 (fewer springs stay in doubt at a loose level).
    tests/test_engine.py checks both against their worst cases from the dense C. (0, 0)
    for other operators, and for a symbol without a positive minimum: they solve every
    round to tol, with no such bound at hand."""
    if not isinstance(op, FFTData):
        return 0.0, 0.0
    sym = op.sym_full
    lam = float(sym.min())
    if not lam > 0.0:
        return 0.0, 0.0      # no positive lower bound (a run refused upstream): no loose rounds
    inv_diag = float(inverse_kernel(sym)[0, 0])
    return float(np.sqrt(inv_diag / lam)), float(np.sqrt(max(op.diag.max() / lam - 1.0, 0.0)))


class ContactState:
    """Contact set, forces and displacements, advanced one dilatation step at a time.

    ``F``, ``u`` and ``contact`` are arrays with one entry per spring, valid after each
    advance. The rounds of a step run compiled for every operator (tfm.kernels.contact:
    no return to Python per CG iteration or per round); the operator and the
    preconditioner enter as their data (``compiled()``, tfm.kernels.ops)."""

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
        self._steps_kept = 0        # steps in a row that changed nothing
        self._base = None
        self._unit = None
        self._unit_set = -1
        op = prob.operator
        self._op = op.compiled()
        pre = prob.precond
        self._pre = pre.compiled() if pre is not None else pre_data()
        # the same on one thread (the same buffers): the tasks that snap_rounds runs side by
        # side when threaded
        self._op1, self._pre1 = self._op, self._pre
        # the loose decision rounds' bounds (FFT operator only; 0: every round to tol)
        self._bound_f, self._bound_u = decision_bounds(self._op)
        self._x0 = np.ascontiguousarray(prob.x0, dtype=float)
        self._f_th = np.ascontiguousarray(prob.f_th, dtype=float)
        self._snap_rounds = self._solve_on_set = None    # compiled entry points (entry_point)
        # the rounds' work space, kept for the run (a tuple: copies of the state share it)
        n = self._x0.size
        self._work = (np.empty((2, 6, n)), np.empty((2, n), dtype=np.int64), np.zeros((2, n), dtype=np.int8))
        # a step's guess, its field and the start of the step (read within advance only)
        self._step_work = (np.empty(n), np.empty(n), np.empty(n), np.empty(n))
        # threads only on grids whose whole box reaches RUN_THREADED_SIZE (tfm/config.py:
        # a short curve gains less than its second busy core costs what runs beside it)
        can_thread = (isinstance(self._op, FFTData) and numba.get_num_threads() > 1
                      and self._op.sym_full.shape[1] >= RUN_THREADED_SIZE)
        if prob.threads not in ("auto", "serial", "threaded"):
            raise ValueError(f"Problem.threads: must be 'auto', 'serial' or 'threaded', got {prob.threads!r}")
        self._overlap = False
        self.entry_guess = EntryGuess()
        self._phase = None           # of the last step (a new phase: a new thread trial)
        self.thread_choice = ThreadChoice() if can_thread and prob.threads == "auto" else None
        if prob.threads != "auto":
            self.threaded = prob.threads == "threaded"

    # What a later step reads besides the problem: saved and restored by tfm.checkpoint.
    CARRIED = ("contact", "F", "u", "_slope", "_uslope", "_last_d", "_set_id", "_steps_kept", "_base",
               "_unit", "_unit_set")

    def carried(self) -> dict:
        """The state a later step reads (arrays, numbers, tuples of them, or None)."""
        return {name: getattr(self, name) for name in self.CARRIED}

    def restore(self, carried: dict) -> None:
        """Continue from ``carried()`` of a state of the same problem."""
        missing = set(self.CARRIED) - set(carried)
        if missing:
            raise ValueError(f"restore: the saved state lacks {sorted(missing)}")
        for name in ("contact", "F", "u"):
            if carried[name].shape != getattr(self, name).shape:
                raise ValueError(f"restore: {name} has shape {carried[name].shape}, the problem "
                                 f"{getattr(self, name).shape}")
        for name in self.CARRIED:
            setattr(self, name, carried[name])

    @property
    def threaded(self) -> bool:
        """Whether the field runs beside the next round's solve and the large transforms are
        spread over the Numba threads (FFT operator; the same bits either way). On one
        thread the two tasks take turns: the path is the same."""
        return self._overlap

    @threaded.setter
    def threaded(self, value: bool):
        if isinstance(self._op, FFTData):
            self._op = self._op._replace(threads=numba.get_num_threads() if value else 1)
            self._overlap = bool(value)
        if self._pre.kind == PRE_FFT:
            self._pre = self._pre._replace(threads=numba.get_num_threads() if value else 1)

    def _rounds(self, d, guess, u_guess, out, solved=False, prepare=False):
        """The rounds of step d (snap_rounds); with ``prepare``, a step that changes
        nothing ends with the base and unit response of its set (prepare_predictions,
        to SKIP_TOL times tol)."""
        prob = self.prob
        stats = np.zeros(N_STATS, dtype=np.int64)
        fstats = np.zeros(N_FSTATS)
        fstats[F_MAX_RES] = out.max_residual
        ug = self.u if u_guess is None else u_guess
        slope = self._slope if self._slope is not None else self.F     # (unread without a slope)
        # prepare_predictions' output (base F and u; unit response x and its field), kept
        # as the new _base and _unit: allocated only when asked for, after the old ones (of
        # an earlier set) are let go, and in two blocks, so that a new base alone frees the
        # old one (one block held 2 N floats more at the peak)
        if prepare:
            self._base = self._unit = None
        shape = (2, self.F.size) if prepare else (2, 0)
        base, unit = np.empty(shape), np.empty(shape)
        args = (float(d), self.contact, self.F, self.u, guess, ug, u_guess is not None, solved,
                self._x0, self._f_th, self._op, self._pre, float(prob.tol), int(prob.max_iter),
                int(prob.max_rounds), prob.snap_rule == "single", float(DECISION_SLACK),
                np.array(prob.round_tols, dtype=float), float(prob.field_level), self._bound_f,
                self._bound_u, stats, fstats,
                *self._work, self.threaded, self.threaded and self.entry_guess.use(), self._op1,
                self._pre1, float(prob.tol * SKIP_TOL) if prepare else 0.0, slope, self._slope is not None,
                base, unit)
        if self._snap_rounds is None:
            self._snap_rounds = entry_point(snap_rounds, args)
        self._snap_rounds(*args)
        out.max_residual = float(fstats[F_MAX_RES])
        out.n_solves += int(stats[S_SOLVES])
        out.solver_failures += int(stats[S_FAILURES])
        out.rounds_exceeded += int(stats[S_EXCEEDED])
        out.refines += int(stats[S_REFINES])
        out.solves_ahead += int(stats[S_AHEAD])
        out.solves_dropped += int(stats[S_DROPPED])
        self.entry_guess.record(int(stats[S_GUESS_KEPT]), int(stats[S_GUESS_DROPPED]))
        if stats[S_PREPARED]:
            self._base = (base[0], base[1], float(d), float(fstats[F_BASE_RES]))
            self._unit = (unit[0], unit[1], float(fstats[F_UNIT_RES]), int(stats[S_UNIT_ITERS]))
            self._unit_set = self._set_id
        elif stats[S_SOLVES] > 0 and self.skip_solves:
            # the step ended on a real solve: the base of later predictions on this set
            self._base = (self.F.copy(), self.u.copy(), float(d),
                          float(fstats[F_LAST_RES] * fstats[F_LAST_BNORM]))
        return (int(stats[S_ROUNDS]), int(stats[S_ITERS]), int(stats[S_SNAPPED]),
                int(stats[S_ENTERED]))

    def _solve_unit(self):
        """x with C_SS x = 1 on the contact set (0 off it), its field w = C x on every
        spring, and ||1 - C_SS x||; warm-started from the last step's dF/dd."""
        prob = self.prob
        idx = np.flatnonzero(self.contact)
        x, w = np.zeros(self.F.size), np.zeros(self.F.size)
        if idx.size == 0:
            return x, w, 0.0, 0
        ones = np.ones(idx.size)
        xs = self._slope[idx].copy() if self._slope is not None else np.zeros(idx.size)
        args = (self._op, self._pre, idx, ones, xs, ones, False, float(prob.tol), int(prob.max_iter), w, True)
        if self._solve_on_set is None:
            self._solve_on_set = entry_point(solve_on_set, args)
        it, conv, res = self._solve_on_set(*args)
        x[idx] = xs
        return x, w, res * np.sqrt(idx.size), it

    def unit_response(self, out: CurveResult | None = None) -> np.ndarray:
        """dF/dd on the current contact set: the full-grid solution of C_SS x = 1 on the
        set, zero off it (F is linear in d while the set is fixed: F(d) = F(d0) + (d - d0) x).
        A new solve is counted in ``out`` (n_solves, solver_iters) when given."""
        if self._unit is None or self._unit_set != self._set_id:
            self._unit = self._solve_unit()
            self._unit_set = self._set_id
            if out is not None and self.contact.any():
                out.n_solves += 1
                out.solver_iters += self._unit[3]
        return self._unit[0].copy()

    def _predict(self, d):
        """F and u at d from the base solution and the unit response of the unchanged set,
        if the residual bound ||r_base|| + |d - d_base| ||r_x|| stays within tol ||b||."""
        if self._base is None or self._unit is None or self._unit_set != self._set_id:
            return False
        Fb, ub, db, rb = self._base
        x, w, rx, _ = self._unit
        c = d - db
        if rb + abs(c) * rx > self.prob.tol * rhs_norm(self.contact, self._x0, d):
            return False
        predicted(Fb, ub, x, w, c, self.F, self.u)
        return True

    # ------------------------------------------------------------------ one step
    def advance(self, d: float, k: int, phase: str, out: CurveResult) -> StepRecord:
        prob = self.prob
        guess, ug, start_F, start_u = self._step_work       # the rounds overwrite the guess
        u_guess = None
        np.copyto(start_F, self.F)
        np.copyto(start_u, self.u)
        # Skip the solve while the set is unchanged: F = F_base + (d - d_base) x.
        solved = self.skip_solves and self._predict(d)
        if not solved and self._slope is not None:     # (a predicted step reads no guess)
            # F and u = C F are both linear in d: C (F + c dF) = u + c du. The known field
            # is the guess's own only if the guess vanishes off the contact set, i.e. no
            # spring snapped in the last step (a snapped spring's dF is -F/dd).
            if extrapolate(self.F, self.u, self._slope, self._uslope, self.contact, d - self._last_d,
                           guess, ug):
                u_guess = ug
        elif not solved:
            np.copyto(guess, self.F)
        choice = self.thread_choice
        if choice is not None:
            if phase != self._phase:
                choice.restart()
            self.threaded = choice.next()
            t0 = time.perf_counter()
        # If this step keeps the set, it has survived two whole steps: its unit response
        # will likely serve the next ones (a receding contact has single steps without a
        # snap between its snaps). A prediction F_base + (d - d_base) x must stay within
        # tol, so both are solved to SKIP_TOL times tol (at tol, the bound failed at the
        # first step), at the end of the step's rounds (prepare_predictions)
        prepare = (self.skip_solves and self._steps_kept >= 1 and prob.tol * SKIP_TOL >= SKIP_MIN_TOL
                   and (self._unit is None or self._unit_set != self._set_id))
        rounds, iters, snapped, entered = self._rounds(d, guess, u_guess, out, solved, prepare)
        if choice is not None:
            choice.record(self.threaded, time.perf_counter() - t0, iters, rounds)
        if iters and self.threaded:
            out.threaded_steps += 1
        self._steps_kept = 0 if snapped or entered else self._steps_kept + 1
        if snapped or entered:
            self._set_id += 1
        # dF/dd for the next step's warm start. Exact while the contact set is unchanged
        # (F is linear in d for a fixed set); still a good guess after small changes.
        if self._last_d is not None and d != self._last_d:
            if self._slope is None:
                self._slope, self._uslope = np.empty_like(self.F), np.empty_like(self.u)
            difference_quotients(self.F, self.u, start_F, start_u, d - self._last_d, self._slope,
                                 self._uslope)
        else:
            self._slope = self._uslope = None
        self._last_d = d
        self._phase = phase
        if (self.contact & prob.edge).any():
            out.edge_steps += 1
        out.solver_iters += iters
        # 0.0 - sum: no contact gives P = +0.0, not -0.0 (printed "P = -0"). np.compress
        # gathers what area[contact] does (the same sum, bit for bit) in half the time
        return StepRecord(k, phase, d, 0.0 - float(self.F.sum()),
                          float(np.compress(self.contact, prob.area).sum()),
                          int(np.count_nonzero(self.contact)), snapped, entered, rounds, iters)

