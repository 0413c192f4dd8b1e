"""Loading protocols: the sequence of dilatation steps applied to a ContactState.

- Displacement control (the paper's Algorithm 1, Sec. 2.1): push the flat in to
  d = -delta_max in steps of ``step``, then pull it off in the same steps until no spring
  touches. One curve row per step.
- Force control: raise the compressive load P = -sum F to ``max_load``, then lower it in
  steps of ``load_step`` into tension until the contact cannot hold the load. The paper
  (Sec. 3.1): "If we did a force-controlled test, the entire contact would break and the
  force drop to zero at the maximum tensile force."

  On a fixed contact set the forces are linear in d, F(d') = F(d) + (d' - d) g with
  g = ContactState.unit_response() (C_SS g = 1), so the d that carries a target load is
  one Newton step away: d' = d + (P(d) - P_target) / sum(g). The step is exact unless
  springs snap or enter; then the set changed, g is recomputed and the step repeated
  until the set holds (the snap rounds of Algorithm 1 inside each load step). Lowering
  the load past what the shrinking contact can carry makes every step snap more springs
  until none is left: that is the jump-off. The last load held before it is refined by
  bisection (each trial starts from a copy of the last held state), so the jump-off force
  is resolved to ``load_step / 2**JUMP_BISECTIONS``, not to ``load_step``.

Every recorded step is passed to ``observe(state, record)`` (progress bars, field
snapshots). Files are written only through ``observe`` and a checkpoint passed in
(tfm.checkpoint: a displacement-controlled run continues from its last saved step).
"""
from __future__ import annotations

import copy
import math
import time
from typing import Callable

import numpy as np

from .checkpoint import DONE, StopRequest
from .progress import say
from .params import MAX_CAP, MAX_STEPS
from .solver import ContactState, CurveResult, Problem, StepRecord

# Bisections of the last load step before the jump-off: resolution load_step / 2**10.
JUMP_BISECTIONS = 10
# A loading move this small (relative to the step or to d) across which the load
# still jumps past the target is a jump into contact (_load_to).
JUMP_MOVE = 1e-9

Observer = Callable[[ContactState, StepRecord], None]


def run(p, prob: Problem, observe: Observer | None = None, checkpoint=None) -> CurveResult:
    """The protocol named by ``p.control`` (a validated tfm.Params). ``checkpoint`` (a
    tfm.checkpoint.Checkpoint, displacement control only) saves the state as the curve goes
    and continues from a saved state."""
    n_load = n_loading_steps(p)
    max_unload = p.max_unload_steps or default_max_unload_steps(p)
    if checkpoint is not None and p.control == "force":
        raise ValueError("checkpoint: force control is not checkpointed")
    # SIGINT and SIGTERM wait for the end of the step in progress, where a checkpointed run
    # saves it first (displacement_control). A run without a checkpoint stops there too:
    # raised inside a compiled call's argument handling the signal came out as a TypeError,
    # and inside a snapshot's write it could leave the stream half written.
    stop = StopRequest(checkpoint.path if checkpoint is not None else None)

    def observe_then_stop(state, rec):
        if observe is not None:
            observe(state, rec)
        if stop.pending and checkpoint is None:
            stop.deliver()

    with stop.installed():
        if p.control == "force":
            out = force_control(prob, p.peak_load, p.load_decrement, p.step, max_unload, observe_then_stop,
                                depth=p.delta_max)
        else:
            out = displacement_control(prob, p.delta_max, p.step, max_unload, observe_then_stop, checkpoint, stop)
        if stop.pending and checkpoint is None:
            stop.deliver()
    return out


def default_max_unload_steps(p) -> int:
    """``max_unload_steps=None``: 20 times the loading steps + 1000; under force control
    also twice the continuum pull-off force in load steps (theory.pull_off_estimate). A
    small preload with strong adhesion needs many more load steps to break than it took
    to load: 100 load levels to 1e-3 then needed some 5,300 steps of 1e-5 to its pull-off
    of 0.053 (spacing 1/32, k_th 0.3), and stopped at the former cap of 3,000, flagged."""
    cap = 20 * n_loading_steps(p) + 1000
    if p.control == "force":
        from .theory import pull_off_estimate
        from .units import force_scale          # theory is in paper units (SI: L* = 1 m)
        tension = pull_off_estimate(p) * force_scale(p)
        cap += math.ceil(min(2.0 * tension / p.load_decrement, MAX_CAP))
    return int(min(cap, MAX_CAP))


def n_loading_steps(p) -> int:
    if p.control == "force":
        return int(np.ceil(p.peak_load / p.load_decrement - 1e-9))
    return int(np.ceil(p.delta_max / p.step - 1e-9))


def displacement_control(prob: Problem, delta_max: float, step: float, max_unload_steps: int,
                         observe: Observer | None = None, checkpoint=None, stop=None) -> CurveResult:
    """Load from d = 0 to d = -delta_max in steps of ``step``, then unload until no spring
    is in contact (or max_unload_steps is reached, which is flagged). With a checkpoint,
    the state is saved after finished steps, and after the step in progress when SIGINT
    or SIGTERM comes (``stop``, a tfm.checkpoint.StopRequest the caller installed); a
    saved state is continued from."""
    out = CurveResult()
    t0 = time.perf_counter()
    state = ContactState(prob)
    n_load = int(np.ceil(delta_max / step - 1e-9))
    first = {"load": 1, "unload": 1}
    before = 0.0                         # compute time of the run before it was resumed
    saved = checkpoint.load() if checkpoint is not None else None
    if saved is not None:
        state.restore(saved.carried)
        out, before = saved.out, saved.elapsed
        if saved.phase == DONE:          # stopped after its last step: nothing to compute
            out.wall_time = before
            return out
        first[saved.phase] = saved.j + 1
        if saved.phase == "unload":
            first["load"] = n_load + 1
    if checkpoint is None:
        return _displacement_steps(state, out, first, n_load, delta_max, step, max_unload_steps,
                                   observe, lambda phase, j: None, t0, before)
    stop = stop or StopRequest(checkpoint.path)      # not installed: no signal is waited for

    def done(phase, j):
        elapsed = before + time.perf_counter() - t0
        if stop.pending:
            if checkpoint.try_save(state, out, phase, j, elapsed):
                say(f"tfm: saved the state after step {len(out.steps)} in {checkpoint.path}")
            stop.deliver()
        else:
            checkpoint.step_done(state, out, phase, j, elapsed)

    out = _displacement_steps(state, out, first, n_load, delta_max, step, max_unload_steps,
                              observe, done, t0, before)
    if stop.pending:                     # it came during the last step: keep the whole curve
        done(DONE, 0)
    elif checkpoint.save_when_done:      # the caller stores the result, then removes it
        checkpoint.try_save(state, out, DONE, 0, out.wall_time)
    return out


def _displacement_steps(state, out, first, n_load, delta_max, step, max_unload_steps, observe,
                        done, t0, before) -> CurveResult:
    """The steps of displacement control from ``first`` on; ``done(phase, j)`` after each
    one that a later step follows."""
    k = len(out.steps)
    for j in range(first["load"], n_load + 1):
        rec = state.advance(-min(j * step, delta_max), k, "load", out)
        _record(out, state, rec, observe)
        k += 1
        done("load", j)
    out.unload_complete = False
    for j in range(first["unload"], max_unload_steps + 1):
        rec = state.advance(-delta_max + j * step, k, "unload", out)
        _record(out, state, rec, observe)
        k += 1
        if rec.n_contact == 0:
            out.unload_complete = True
            break
        done("unload", j)
    out.wall_time = before + time.perf_counter() - t0
    return out


def force_control(prob: Problem, peak_load: float, load_step: float, step: float,
                  max_unload_steps: int, observe: Observer | None = None, depth: float = math.inf) -> CurveResult:
    """Raise P to ``peak_load`` in steps of ``load_step``, lower it in the same steps until
    the contact breaks; refine the last load held by bisection. While loading, the flat
    moves by at most ``step`` at a time (_load_to); ``step`` is also how far it moves to
    make the first contact when unloading has none left. ``depth`` is the non-adhesive
    depth of the peak load: no load step moves the flat more than twice that in steps."""
    out = CurveResult()
    t0 = time.perf_counter()
    state = ContactState(prob)
    d, k = 0.0, 0
    n_load = int(np.ceil(peak_load / load_step - 1e-9))
    max_moves = min(MAX_STEPS, math.ceil(2.0 * depth / step) + 10) if math.isfinite(depth) else MAX_STEPS
    for j in range(1, n_load + 1):
        rec, d, _ = _hold(state, min(j * load_step, peak_load), d, step, k, "load", out, max_moves)
        _record(out, state, rec, observe)
        k += 1
    out.unload_complete = False
    held_load, held_state, held_d = peak_load, _copy_state(state), d
    for j in range(1, max_unload_steps + 1):
        target = peak_load - j * load_step
        rec, d, ok = _hold(state, target, d, step, k, "unload", out)
        if ok:
            _record(out, state, rec, observe)
            k += 1
            held_load, held_state, held_d = target, _copy_state(state), d
            continue
        # the contact broke between held_load and target: bisect on copies of the held state
        broken, broken_rec, hi = state, rec, target
        for _ in range(JUMP_BISECTIONS):
            mid = 0.5 * (held_load + hi)
            trial = _copy_state(held_state)
            trec, tdd, tok = _hold(trial, mid, held_d, step, k, "unload", out)
            if tok:
                _record(out, trial, trec, observe)
                k += 1
                held_load, held_state, held_d = mid, _copy_state(trial), tdd
            else:
                broken, broken_rec, hi = trial, trec, mid
        # The row after the jump: no contact, no load, at the d of the last load held. Where
        # the flat goes after the jump is not defined under force control (the d at which
        # the Newton steps found no spring left is an artefact); at this d the cycle's loop
        # closes with a vertical drop, as the pull-off's under displacement control, so
        # the hysteresis is the work done up to the jump (a line to the artefact's d added
        # 36 % at 1/64), and plots draw the jump as a drop.
        broken_rec.step, broken_rec.d = k, held_d
        _record(out, broken, broken_rec, observe)
        out.unload_complete = True
        break
    out.wall_time = time.perf_counter() - t0
    return out


def _hold(state: ContactState, target: float, d: float, step: float, k: int, phase: str,
          out: CurveResult, max_moves: int = MAX_STEPS) -> tuple[StepRecord, float, bool]:
    """Move the flat until the contact carries the compressive load ``target`` on a set
    that no longer changes. Returns the step's record (counts summed over the Newton
    steps), the final d, and False if the contact broke (no spring left in contact)."""
    if phase == "load":
        return _load_to(state, target, d, step, k, out, max_moves)
    return _newton_hold(state, target, d, step, k, phase, out)


def _load(state: ContactState) -> float:
    return -float(state.F.sum())


def _newton(state: ContactState, target: float, d: float, out: CurveResult) -> tuple[float, int]:
    """The d at which the current contact set carries ``target`` (exact while the set
    holds: F is linear in d on it), and the CG iterations of the unit response it took."""
    before = out.solver_iters
    slope = float(state.unit_response(out).sum())  # d(sum F)/dd > 0 on the set
    return d + (_load(state) - target) / slope, out.solver_iters - before


def _adopt(state: ContactState, trial: ContactState) -> None:
    """Make ``state`` the tried copy (_copy_state) that was taken."""
    state.__dict__.update(vars(trial))


def _load_to(state: ContactState, target: float, d: float, step: float, k: int,
             out: CurveResult, max_moves: int = MAX_STEPS) -> tuple[StepRecord, float, bool]:
    """A loading step: the flat moves in until the contact carries ``target``, never past
    it, and by at most ``step`` at a time. On a fixed set the load is linear in d; springs
    that enter as the flat moves in only stiffen the contact, so the Newton step on the
    current set reaches the target load or goes beyond it. Beyond it, springs pulled in
    would stay (the threshold holds them in tension when the flat backs off): a state that
    loading to the target never makes, with a larger contact and indent than displacement
    control's loading branch at the same load (before: +85 % indent at the first load
    steps at spacing 1/32). So every move is tried on a copy of the state: one that carries
    at most the target is taken (a loading move), one that carries more bounds the next
    tries, which halve the bracket. Moves no longer than ``step`` make the loading path
    one of displacement control at that step or finer (one deep move takes in, at once,
    springs that smaller ones would not). If the load jumps across the target within a
    vanishing move (springs pulled in by their neighbours' tension), the state beyond the
    jump is taken and the flat backs off to the target on its set, as a force-controlled
    flat would."""
    rounds = iters = snapped = entered = 0
    over = None                           # (d, state, record) of the shallowest try beyond the target
    rec = None
    # max_rounds caps the Newton and bisection tries; whole steps in below the target are
    # the way down (a fine step under a coarse load step takes thousands: the loading
    # stopped at a quarter of max_load), capped by max_moves
    tries = moves = 0
    while tries < state.prob.max_rounds and moves < max_moves:
        if state.contact.any():
            newton, used = _newton(state, target, d, out)
            iters += used
        else:
            newton = -np.inf              # no contact yet: one step in
        d_try = max(newton, d - step)     # at most one step in
        if over is not None and d_try <= over[0]:
            d_try = 0.5 * (d + over[0])     # the middle of the bracket
        exact_try = d_try == newton       # the Newton step itself: exact if the set holds
        trial = _copy_state(state)
        trec = trial.advance(d_try, k, "load", out)
        rounds += trec.rounds
        iters += trec.solver_iters
        if exact_try and trec.n_snapped == 0 and trec.n_entered == 0:
            _adopt(state, trial)           # the Newton step held its set: exact
            d, rec = d_try, trec
            break
        if _load(trial) <= target:
            _adopt(state, trial)           # a move that stays below the target
            snapped += trec.n_snapped
            entered += trec.n_entered
            if d_try == d - step:
                moves += 1
            else:
                tries += 1
            d, rec = d_try, trec
        else:
            tries += 1
            over = (d_try, trial, trec)
        if over is not None and abs(over[0] - d) <= JUMP_MOVE * max(step, abs(d)):
            # the load jumps across the target here: take the state beyond, back off on its set
            d, trial, trec = over
            _adopt(state, trial)
            snapped += trec.n_snapped
            entered += trec.n_entered
            rec, d, _ = _newton_hold(state, target, d, step, k, "load", out)
            rounds += rec.rounds
            iters += rec.solver_iters
            snapped += rec.n_snapped
            entered += rec.n_entered
            break
    else:
        # flagged; the state is the last one taken
        if moves >= max_moves:
            out.loads_short += 1
        else:
            out.rounds_exceeded += 1
        if rec is None:                   # every try went beyond: the shallowest of them
            d, trial, rec = over
            _adopt(state, trial)
    rec.rounds, rec.solver_iters, rec.n_snapped, rec.n_entered = rounds, iters, snapped, entered
    return rec, d, rec.n_contact > 0


def _newton_hold(state: ContactState, target: float, d: float, step: float, k: int, phase: str,
                 out: CurveResult) -> tuple[StepRecord, float, bool]:
    """Newton steps on the current set until one holds its set (unloading: springs that
    snap as the flat backs off only soften the contact, and the bisection of the jump-off
    in force_control refines the last load held)."""
    prob = state.prob
    rounds = iters = snapped = entered = 0
    rec = None
    for _ in range(prob.max_rounds):
        had_contact = bool(state.contact.any())
        if not had_contact:
            if rec is not None and phase == "unload":
                break
            d_new = d - step          # bring the flat down to the first contact
        else:
            d_new, used = _newton(state, target, d, out)
            iters += used
        rec = state.advance(d_new, k, phase, out)
        d = d_new
        rounds += rec.rounds
        iters += rec.solver_iters
        snapped += rec.n_snapped
        entered += rec.n_entered
        if rec.n_contact == 0 and phase == "unload":
            break
        if had_contact and rec.n_snapped == 0 and rec.n_entered == 0:
            break                            # the Newton step was on this set: exact
    else:
        out.rounds_exceeded += 1
    rec.rounds, rec.solver_iters, rec.n_snapped, rec.n_entered = rounds, iters, snapped, entered
    return rec, d, rec.n_contact > 0


def _copy_state(state: ContactState) -> ContactState:
    """An independent copy of the state's arrays (the problem and operator are shared)."""
    twin = copy.copy(state)
    for name, value in vars(state).items():
        if isinstance(value, np.ndarray):
            setattr(twin, name, value.copy())
    return twin


def _record(out: CurveResult, state: ContactState, rec: StepRecord, observe: Observer | None) -> None:
    out.steps.append(rec)
    if observe is not None:
        observe(state, rec)
