"""The compiled contact engine (tfm.kernels.contact) against its slow twins.

* the dense reference (np.linalg.solve on the dense C, tests/naive.py) at 1/64;
* the old Python engine (tests/reference_engine.py, run live) at 1/128;
* the dense solve of C_SS x = 1 for ContactState.unit_response;
* itself on 1 and 2 threads (bitwise), on a grid large enough for threaded transforms,
  and with the field beside the next round's solve against one after the other (bitwise).
"""
import numba
import numpy as np
import pytest

from naive import algorithm1_dense
from reference_engine import reference_curve
from tfm.config import SKIP_TOL
from tfm import Params, simulate
from tfm.geometry import heights, make_layout
from tfm.operators import kernel_spec
from tfm.protocol import run
from tfm.simulate import build_problem
from tfm.solver import ContactState, CurveResult

STANDARD = dict(alpha=0.75, k_th=0.02, radius=1.0, shape="paraboloid", max_indent=0.05, step=2.5e-4)


def dense_compliance(layout, spec):
    """C_ij = 1/r_ij, C_ii = diag (the double loop of naive.py, vectorized for N ~ 1500)."""
    r = np.hypot(layout.x[:, None] - layout.x[None, :], layout.y[:, None] - layout.y[None, :])
    np.fill_diagonal(r, 1.0)
    C = 1.0 / r
    np.fill_diagonal(C, spec.diag)
    return C


@pytest.mark.parametrize("threads, skip", [("serial", True), ("threaded", True), ("serial", False)])
def test_whole_curve_matches_dense_reference_at_1_64(threads, skip):
    """The standard curve at 1/64, preloaded to 0.03 in steps of 1.5e-3 to keep the dense
    solves short (1089 springs, contact sets up to ~400). Threaded: the field of each round
    whose springs snap runs beside the next round's solve (on one thread, in turn). With
    skip_solves (the default) the steps of an unchanged set are predicted, not solved."""
    p = Params.from_dict(dict(STANDARD, spacing="1/64", max_indent=0.03, step=1.5e-3, tol=1e-12))
    prob, layout = build_problem(p)
    prob.threads = threads
    prob.skip_solves = skip
    out = run(p, prob)
    unsolved = sum(s.rounds for s in out.steps) - out.n_solves
    assert (unsolved > 10) == skip             # rounds without a solve: predicted steps
    d = np.array([s.d for s in out.steps])
    force = np.array([s.force for s in out.steps])
    C = dense_compliance(layout, kernel_spec(p, layout))
    ref = algorithm1_dense(C, heights(p, layout), p.k_th * layout.area ** p.alpha, d)
    assert np.array_equal([s.n_contact for s in out.steps], ref[:, 2])
    # solve tolerance 1e-12 relative; condition number of C_SS ~ 10^2: forces to 1e-9
    assert np.allclose(force, ref[:, 1], rtol=0, atol=1e-9 * np.abs(ref[:, 1]).max())
    assert (out.solves_ahead > 0) == (threads == "threaded")


def test_a_mistyped_thread_mode_is_refused():
    prob, _ = build_problem(Params.from_dict(dict(STANDARD, spacing="1/16")))
    prob.threads = "threads"
    with pytest.raises(ValueError, match="Problem.threads: must be 'auto', 'serial' or 'threaded'"):
        ContactState(prob)


def test_the_field_beside_the_next_solve_gives_the_serial_curve_bit_for_bit():
    """The whole standard curve at 1/64, serial and threaded: the same forces and fields at
    every step, bit for bit; most rounds of the receding contact ran their solve beside the
    field of the round before."""
    p = Params.from_dict(dict(STANDARD, spacing="1/64"))
    runs = []
    for threads in ("serial", "threaded"):
        prob, _ = build_problem(p)
        prob.threads = threads
        seen = []
        out = run(p, prob, observe=lambda state, rec: seen.append((state.F.copy(), state.u.copy())))
        runs.append((out, seen))
    (a, fa), (b, fb) = runs
    assert len(fa) == len(fb) and all(np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1])
                                      for x, y in zip(fa, fb))
    assert (a.n_solves, a.solver_iters) == (b.n_solves, b.solver_iters)
    snapping = sum(s.rounds - 1 for s in b.steps if s.n_snapped > 0)
    assert a.solves_ahead == 0 and b.solves_ahead > snapping // 2
    # the summary's threaded_steps: none serial, every step with a solve when threaded
    assert a.threaded_steps == 0
    assert b.threaded_steps == sum(s.solver_iters > 0 for s in b.steps) > 0


def test_a_solve_beside_a_field_that_finds_an_entry_is_dropped_without_a_trace():
    """A round where springs snap and others enter: the next round's solve, run beside the
    field on the guess that nothing enters, is stopped and dropped, and the step ends with
    the bits of the serial one. Made by hand at 1/64 (the curves tried never enter while
    they snap): a third of the tensile springs get a tenth of their force as threshold, and
    four of the nearest free springs are raised into the flat."""
    p = Params.from_dict(dict(STANDARD, spacing="1/64"))
    runs = []
    for threads in ("serial", "threaded"):
        prob, _ = build_problem(p)
        prob.threads = threads
        state, out = ContactState(prob), CurveResult()
        for k, d in enumerate((-0.005, -0.01, -0.015)):
            state.advance(d, k, "load", out)
        tensile = np.flatnonzero(state.contact & (state.F > 0))
        state._f_th[tensile[::3]] = 0.1 * state.F[tensile[::3]]
        gap = -0.0155 - state._x0 - state.u
        near = np.flatnonzero(~state.contact & (gap > 0))
        near = near[np.argsort(gap[near])][:12:3]
        state._x0[near] += gap[near] + 1e-3
        rec = state.advance(-0.0155, 3, "load", out)
        assert rec.n_snapped > 0 and rec.n_entered >= 4
        runs.append((state.F.copy(), state.u.copy(), state.contact.copy(), out))
    a, b = runs
    assert all(np.array_equal(x, y) for x, y in zip(a[:3], b[:3]))
    assert a[3].solves_dropped == 0 and b[3].solves_dropped >= 1
    assert (a[3].n_solves, a[3].solver_iters) == (b[3].n_solves, b[3].solver_iters)


def test_classification_follows_algorithm_1s_rules():
    """_classify (and its snap part, _snap_check, on the contact set alone) against the
    rules written out in NumPy, on random forces and gaps around their decision lines:
    the marks, the counts, the springs within the bounds, the worst snap and entry."""
    from tfm.kernels.contact import _classify, _snap_check

    rng = np.random.default_rng(3)
    N = 500
    contact = rng.random(N) < 0.6
    f_th = rng.uniform(1e-3, 2e-3, N)
    F = np.where(contact, f_th + rng.normal(0.0, 2e-4, N), 0.0)
    x0 = rng.normal(0.0, 1e-3, N)
    u = rng.normal(0.0, 1e-3, N)
    d = 1e-3
    idx = np.flatnonzero(contact)
    for rel, bf, bu in ((1e-9, -1.0, -1.0), (1e-9, 1e-4, 1e-4), (0.1, 1e-5, 2e-4)):
        g_snap = F - (f_th + rel * np.abs(F[idx]).max())
        g_into = x0 + u - (d + rel * max(abs(d), np.abs(u).max()))
        snap, into = contact & (g_snap > 0), ~contact & (g_into > 0)
        unsure = np.sum(contact & (np.abs(g_snap) <= bf)) + np.sum(~contact & (np.abs(g_into) <= bu))
        worst_snap = int(np.flatnonzero(snap)[np.argmax((F - f_th)[snap])])
        worst_into = int(np.flatnonzero(into)[np.argmax((x0 + u)[into])])
        marks = np.full(N, 7, dtype=np.int8)
        got = _classify(d, idx, contact, F, u, x0, f_th, rel, bf, bu, marks)
        assert got == (snap.sum(), into.sum(), unsure, worst_snap, worst_into)
        assert np.array_equal(marks, np.where(snap, 1, np.where(into, 2, 0)))
        assert snap.sum() > 0 and into.sum() > 0
        marks[:] = 7
        assert _snap_check(idx, F[idx], f_th, rel, bf, marks) == (
            snap.sum(), np.sum(contact & (np.abs(g_snap) <= bf)), worst_snap)
        assert np.array_equal(marks[idx], snap[idx].astype(np.int8))


def test_box_places_and_bounds_agree_with_division_for_any_order():
    """One integer division per row: the places and bounds of the division per spring, for
    sorted and for shuffled flat indices."""
    from tfm.kernels.grid import index_bounds
    from tfm.kernels.ops import box_places

    rng = np.random.default_rng(5)
    n = 37
    idx = np.sort(rng.choice(n * n, 300, replace=False))
    for order in (idx, rng.permutation(idx)):
        i, j = order // n, order % n
        assert index_bounds(n, order) == (i.min(), i.max(), j.min(), j.max())
        at = box_places(order, n, 3, 2, 80, np.empty(order.size, dtype=np.int64))
        assert np.array_equal(at, (i - 3) * 80 + j - 2)


def test_blocked_dot_sums_its_lanes_and_blocks_in_a_fixed_order():
    """The compiled dot product against a plain-Python twin of its definition (blocks of
    REDUCTION_BLOCK, element i of a block in lane i % DOT_LANES, the lanes added pairwise,
    the blocks in order): the same bits, at lengths around the lane and block edges; and
    within a few units of round-off of the exact sum (math.fsum)."""
    import math
    from tfm.config import REDUCTION_BLOCK
    from tfm.kernels.grid import DOT_LANES, blocked_dot

    def twin(a, b):
        total = 0.0
        for lo in range(0, a.size, REDUCTION_BLOCK):
            lanes = [0.0] * DOT_LANES
            for i in range(lo, min(a.size, lo + REDUCTION_BLOCK)):
                lanes[(i - lo) % DOT_LANES] += float(a[i]) * float(b[i])
            width = DOT_LANES // 2
            while width:
                for j in range(width):
                    lanes[j] += lanes[j + width]
                width //= 2
            total += lanes[0]
        return total

    rng = np.random.default_rng(11)
    for n in (0, 1, 15, 16, 17, 4095, 4096, 4097, 10007):
        a, b = rng.normal(size=n), rng.normal(size=n)
        got = blocked_dot(a, b)
        assert got == twin(a, b), n
        # each partial sum carries at most its length in units of round-off of |a||b|
        exact = math.fsum(float(x) * float(y) for x, y in zip(a, b))
        assert abs(got - exact) <= 1e-16 * n * float(np.abs(a) @ np.abs(b)) + 1e-300, n


def test_whole_curve_matches_the_old_engine_at_1_128():
    """Every step's contact count equals the old Python engine's, run live."""
    p = Params.from_dict(dict(STANDARD, spacing="1/128"))
    res = simulate(p)
    old = reference_curve(p)
    assert np.array_equal(res.curve["n_contact"].to_numpy(), [s.n_contact for s in old.steps])
    f_old = np.array([s.force for s in old.steps])
    pull_old = max(float((-f_old).max()), 0.0)
    # both solve to tol 1e-10 with the same decisions; the pull-off is a sum of forces
    # each within ~1e-10 relative, so 1e-6 leaves four orders of margin
    assert res.summary["pull_off_force"] == pytest.approx(pull_old, rel=1e-6)


def test_unit_response_solves_c_ss_x_equals_one():
    p = Params.from_dict(dict(STANDARD, spacing="1/32", max_indent=0.02, step=2e-3, tol=1e-12))
    prob, layout = build_problem(p)
    state = ContactState(prob)
    out = CurveResult()
    for k, d in enumerate((-0.005, -0.01, -0.02)):
        state.advance(d, k, "load", out)
    x = state.unit_response()
    idx = np.flatnonzero(state.contact)
    C = dense_compliance(layout, kernel_spec(p, layout))
    ref = np.linalg.solve(C[np.ix_(idx, idx)], np.ones(idx.size))
    assert np.all(x[~state.contact] == 0.0)
    # tol 1e-12 on a system of condition ~10^2
    assert np.allclose(x[idx], ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    # F is linear in d on a fixed set: the next step, if the set stays, moves by c x
    F0 = state.F.copy()
    rec = state.advance(-0.0201, 3, "load", out)
    if rec.n_snapped == rec.n_entered == 0:
        assert np.allclose(state.F, F0 - 1e-4 * x, rtol=0, atol=1e-9 * np.abs(F0).max())


def test_a_set_kept_two_steps_gets_its_base_and_unit_response_from_the_compiled_step():
    """prepare_predictions (at the end of a step's rounds): once a set has survived two
    steps, the base F at d and x with C_SS x = 1 match the dense solves, and the steps that
    follow on the set are predicted from them (no solve), matching the dense F too."""
    p = Params.from_dict(dict(STANDARD, spacing="1/32", max_indent=0.02, step=2e-3, tol=1e-12))
    prob, layout = build_problem(p)
    state, out = ContactState(prob), CurveResult()
    for k, d in enumerate((-0.005, -0.01, -0.02)):
        state.advance(d, k, "load", out)
    C = dense_compliance(layout, kernel_spec(p, layout))
    prepared_at = None
    for k, d in enumerate(-0.02 + 1e-6 * np.arange(1, 6), start=3):   # tiny unloading moves
        solves = out.n_solves
        rec = state.advance(d, k, "unload", out)
        assert rec.n_snapped == rec.n_entered == 0                     # the set holds
        if prepared_at is None and state._unit is not None and state._unit_set == state._set_id:
            prepared_at = d
            idx = np.flatnonzero(state.contact)
            C_SS = C[np.ix_(idx, idx)]
            x, w, rx, _ = state._unit
            ref = np.linalg.solve(C_SS, np.ones(idx.size))
            assert np.all(x[~state.contact] == 0.0)
            # solved to tol * SKIP_TOL = 1e-13 on a system of condition ~10^2
            assert np.allclose(x[idx], ref, rtol=0, atol=1e-10 * np.abs(ref).max())
            assert np.allclose(w, C[:, idx] @ x[idx], rtol=0, atol=1e-10 * np.abs(w).max())
            Fb, ub, db, rb = state._base
            assert db == d and rx < 1e-12 * np.sqrt(idx.size) and rb >= 0.0
        elif prepared_at is not None:
            assert out.n_solves == solves                               # predicted, not solved
        idx = np.flatnonzero(state.contact)
        F_ref = np.linalg.solve(C[np.ix_(idx, idx)], d - prob.x0[idx])
        # tol 1e-12 (solved) or a prediction within it, at condition ~10^2
        assert np.allclose(state.F[idx], F_ref, rtol=0, atol=1e-9 * np.abs(F_ref).max())
    assert prepared_at is not None and prepared_at < d


def test_a_base_solve_that_does_not_converge_is_reported():
    """The base of the predictions replaces the step's F (prepare_predictions): asked for
    1e-15 relative (tol 1e-14 times SKIP_TOL) from a solution to 1e-12 with no CG iteration
    allowed (one was enough: the FFT preconditioner is nearly C^-1 at 1/32), it cannot get
    there, and the run's failure count and worst residual say so, as for any tol-solve,
    instead of keeping a quietly worse F."""
    p = Params.from_dict(dict(STANDARD, spacing="1/32", max_indent=0.02, step=2e-3, tol=1e-12))
    prob, _ = build_problem(p)
    state, out = ContactState(prob), CurveResult()
    for k, d in enumerate((-0.005, -0.01, -0.02)):
        state.advance(d, k, "load", out)
    assert out.solver_failures == 0
    prob.max_iter, prob.tol = 0, 1e-14
    state._rounds(-0.02, state.F.copy(), None, out, solved=True, prepare=True)
    assert out.solver_failures == 1 and out.max_residual > prob.tol * SKIP_TOL


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 Numba threads")
@pytest.mark.parametrize("skip", [False, True])
def test_compiled_engine_is_bitwise_independent_of_thread_count(skip):
    """A 513 x 513 grid: its transforms (P >= 192) take the threaded path on 2 threads."""
    p = Params.from_dict(dict(STANDARD, spacing="1/128", extent=2.0, max_indent=0.01, step=1e-3))
    prob, layout = build_problem(p)
    prob.skip_solves = skip
    before = numba.get_num_threads()
    runs = []
    try:
        for nt in (1, 2):
            numba.set_num_threads(nt)
            state, out = ContactState(prob), CurveResult()
            state.thread_choice = None   # no switching between modes: one path throughout
            state.threaded = nt > 1      # the threaded path even where it would not pay
            recs = [state.advance(-0.001 * (k + 1), k, "load", out) for k in range(4)]
            runs.append((state.F.copy(), state.u.copy(), [r.force for r in recs]))
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


@pytest.mark.slow
def test_pull_off_at_1_512_is_converged_in_the_tolerance():
    p = Params.from_dict(dict(STANDARD, spacing="1/512"))
    a = simulate(p).summary["pull_off_force"]
    b = simulate(p.replace(tol=1e-12)).summary["pull_off_force"]
    # decisions carry a slack of 10 tol; at tol 1e-10 the pull-off must not move by 1e-5
    assert a == pytest.approx(b, rel=1e-5)


def test_threads_are_used_only_where_they_can_pay():
    """One thread, or a box below THREADED_SIZE: never threaded, without timing anything.
    Otherwise the choice is a timing (machine-dependent), so only its type is checked; the
    bits do not depend on it (test above)."""
    from tfm.kernels.fft import THREADED_SIZE, fast_len, symbol, threads_pay

    small = symbol(1e300, 1 / 64, 3.8, fast_len(2 * 40 - 1))
    large = symbol(1e300, 1 / 64, 3.8, fast_len(2 * 100 - 1))
    assert small.shape[1] < THREADED_SIZE <= large.shape[1]       # P (symbols are transposed)
    assert threads_pay(40, small, 2) is False
    assert threads_pay(100, large, 1) is False
    assert isinstance(threads_pay(100, large, 2), bool)


def test_thread_choice_holds_the_mode_that_was_faster_per_unit_of_work():
    """ThreadChoice alternates the modes for TRIAL steps each, then holds the one with the
    smaller wall time per unit of work (the median of the pairs' ratios) for HOLD steps, and
    tries again (synthetic times)."""
    from tfm.solver import ThreadChoice

    def cycle(choice, cost):                  # cost[mode]: seconds per unit of work
        modes = []
        for k in range(2 * choice.TRIAL + choice.HOLD):
            mode = choice.next()
            iters = 3 + k % 3                # steps of unequal work (+ 1 round + 1)
            choice.record(mode, cost[mode] * (iters + 2), iters, 1)
            modes.append(mode)
        return modes

    choice = ThreadChoice()
    trial = 2 * ThreadChoice.TRIAL
    modes = cycle(choice, {True: 1.0, False: 2.0})
    assert modes[:trial] == [True, False] * ThreadChoice.TRIAL
    assert all(modes[trial:])                          # threaded was faster: held
    modes = cycle(choice, {True: 3.0, False: 2.0})     # the second core got busy
    assert modes[:trial] == [True, False] * ThreadChoice.TRIAL
    assert not any(modes[trial:])
    # one serial step far cheaper than its neighbours (a step of another kind) does not
    # turn the choice: the median of the pairs' ratios
    odd = iter([0.01] + [2.0] * (2 * ThreadChoice.TRIAL + ThreadChoice.HOLD))

    class Odd(dict):
        def __getitem__(self, mode):
            return 1.0 if mode else next(odd)
    modes = cycle(choice, Odd())
    assert all(modes[trial:])
    # steps without a solve (predicted) do the same in both modes: they neither take a
    # trial's place nor count, however their times fall
    choice = ThreadChoice()
    modes = []
    for k in range(2 * ThreadChoice.TRIAL):
        mode = choice.next()
        choice.record(mode, 1.0 if mode else 0.1, 0, 1)       # serial looks 10x faster
        assert choice.next() == mode                           # the same trial slot again
        choice.record(mode, 1.0 if mode else 2.0, 4, 1)        # a solve: threaded is faster
        modes.append(mode)
    assert modes == [True, False] * ThreadChoice.TRIAL
    assert choice.next() is True


def test_entry_guess_is_used_while_it_holds_and_probed_otherwise():
    """EntryGuess: a step's first round predicts entries from its guess while at least RATE
    of the recent predictions held; after a run of failures only every PROBE-th step tries,
    and predictions that hold again turn it back on."""
    from tfm.solver import EntryGuess

    g = EntryGuess()
    assert g.use()                                   # no evidence yet: try
    for _ in range(10):
        g.record(0, 1)                               # dropped, step after step
    uses = [g.use() for _ in range(3 * EntryGuess.PROBE)]
    probes = [k for k, u in enumerate(uses) if u]
    assert len(probes) == 3 and np.all(np.diff(probes) == EntryGuess.PROBE)   # probes only
    g.record(0, 0)                                   # a step that predicted nothing: no evidence
    assert [g.use() for _ in range(EntryGuess.PROBE)].count(True) == 1
    for _ in range(30):
        g.record(1, 0)                               # the probes hold again
    assert g.use()


def test_a_run_switching_modes_gives_the_bits_of_a_serial_run():
    """The thread choice switches modes from step to step; the curve is that of one thread."""
    if numba.get_num_threads() < 2:
        pytest.skip("needs 2 Numba threads")
    p = Params.from_dict(dict(STANDARD, spacing="1/128", extent=2.0, max_indent=0.01, step=1e-3))
    prob, layout = build_problem(p)
    runs = []
    for switching in (False, True):
        state, out = ContactState(prob), CurveResult()
        assert state.thread_choice is not None            # 513 x 513: P >= THREADED_SIZE
        if not switching:
            state.thread_choice = None
            state.threaded = False
        recs = [state.advance(-0.001 * (k + 1), k, "load", out) for k in range(6)]
        runs.append((state.F.copy(), [r.force for r in recs]))
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]


def test_loose_decision_rounds_rest_on_rigorous_bounds():
    """snap_rounds accepts a loose round only inside bounds (tfm.solver.decision_bounds) on
    how far F_k, and u_i off the set, can move per unit change of the residual, for any
    contact set. Checked against their exact worst cases from the dense C at 1/32: the
    largest row 2-norm of C_SS^-1, and the largest 2-norm of C_SS^-1 c_i for a spring i off
    the set (c_i: its couplings to the set), on the whole grid, a contact-like disc, a ring
    and a random half of the springs. The bounds may only be larger. bound_f is nearly
    reached on the disc (its two inequalities are tight there: an inner spring's inverse
    diagonal is the circulant's, and the worst residual change follows the smallest
    eigenvector; 1.13x measured): a bound loose by 20 % or more would mean a wrong K_0 or
    lam. bound_u passes through more inequalities (3.2x the disc's worst case)."""
    p = Params.from_dict(dict(STANDARD, spacing="1/32", max_indent=0.02))
    prob, layout = build_problem(p)
    state = ContactState(prob)
    bound_f, bound_u = state._bound_f, state._bound_u
    C = dense_compliance(layout, kernel_spec(p, layout))
    r = np.hypot(layout.x, layout.y)
    sets = {"grid": np.arange(C.shape[0]), "disc": np.flatnonzero(r < 0.3),
            "ring": np.flatnonzero((r > 0.15) & (r < 0.3)),
            "random": np.flatnonzero(np.random.default_rng(3).random(C.shape[0]) < 0.5)}
    for name, idx in sets.items():
        inv = np.linalg.inv(C[np.ix_(idx, idx)])
        worst_f = np.sqrt((inv ** 2).sum(axis=1)).max()
        assert worst_f <= bound_f, name
        off = np.setdiff1d(np.arange(C.shape[0]), idx)
        if off.size:
            worst_u = np.sqrt(((inv @ C[np.ix_(idx, off)]) ** 2).sum(axis=0)).max()
            assert worst_u <= bound_u, name
        if name == "disc":
            assert bound_f < 1.2 * worst_f


def test_no_decision_bounds_without_a_positive_symbol_or_for_other_operators():
    """decision_bounds gives (0, 0), every round to tol, where it has no lower bound on the
    eigenvalues: a symbol with a non-positive minimum (the square root of a negative number
    was NaN), or an operator other than the FFT one."""
    from tfm.solver import decision_bounds

    p = Params.from_dict(dict(STANDARD, spacing="1/32", max_indent=0.02))
    prob, _ = build_problem(p)
    op = prob.operator.compiled()
    assert min(decision_bounds(op)) > 0
    flat = op.sym_full.copy()
    flat[0, 0] = 0.0
    assert decision_bounds(op._replace(sym_full=flat)) == (0.0, 0.0)
    direct, _ = build_problem(p.replace(operator="direct"))
    assert decision_bounds(direct.operator.compiled()) == (0.0, 0.0)


@pytest.mark.parametrize("spacing", ["1/64", "1/128"])
def test_loose_decision_rounds_change_no_decision(spacing):
    """The standard curve with decision-only rounds stopped at ROUND_TOLS and with every
    round solved to tol: the same contact count at every step, and forces within what the
    two tol-solves can differ by (tol 1e-10 relative on ||b||, condition ~10^2: 1e-7 of the
    largest force leaves margin). The loose path must actually have been taken."""
    p = Params.from_dict(dict(STANDARD, spacing=spacing))
    runs = []
    for loose in (True, False):
        prob, _ = build_problem(p)
        if not loose:
            prob.round_tols = ()
        runs.append(run(p, prob))
    a, b = runs
    assert a.refines > 0 and b.refines == 0
    assert a.solver_iters < b.solver_iters
    assert [s.n_contact for s in a.steps] == [s.n_contact for s in b.steps]
    fa = np.array([s.force for s in a.steps])
    fb = np.array([s.force for s in b.steps])
    assert np.allclose(fa, fb, rtol=0, atol=1e-7 * np.abs(fb).max())


def test_stopped_and_continued_cg_is_one_solve():
    """cg_run stopped at a loose residual and carried on to tol repeats the operations of
    one uninterrupted solve: the same iterate, bit for bit, after the same number of
    iterations (what lets snap_rounds stop a solve for a decision at no cost)."""
    from tfm.kernels.contact import cg_run, cg_start, cg_workspace, solve_on_set
    p = Params.from_dict(dict(STANDARD, spacing="1/64"))
    prob, layout = build_problem(p)
    op, pre = prob.operator.compiled(), prob.precond.compiled()
    idx = np.flatnonzero(np.hypot(layout.x, layout.y) < 0.2)
    b = 0.01 - prob.x0[idx]
    whole = np.zeros(idx.size)
    it_whole, conv, _ = solve_on_set(op, pre, idx, b, whole, b, False, 1e-10, 500, np.zeros(0), False)
    assert conv and it_whole > 3
    parts = np.zeros(idx.size)
    ws = cg_workspace(op, pre, idx)
    state = cg_start(op, ws, idx, b, parts, b, False, np.empty((4, idx.size)))
    its = [cg_run(op, pre, ws, state, idx, parts, tol, 500)[0] for tol in (1e-4, 1e-7, 1e-10)]
    assert min(its) > 0 and sum(its) == it_whole
    assert np.array_equal(parts, whole)
