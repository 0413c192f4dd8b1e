"""Meaningful-run guards and the memory estimate: checked before a run starts.

A parameter record can be valid and still describe a run whose numbers mean nothing.
``check(p)`` refuses such a run with a ``GuardError`` (a ParameterError naming the
parameter, the measured reason and the override) unless ``p.allow`` names the guard,
and returns notes to state before the run (a capped automatic preload).

Each threshold was measured on the paraboloid pull-off (R = 1, K_th = 0.02,
alpha = 0.75, max_indent = 0.05; reference 3.19e-3 at spacing 1/256):

- ``coarse``: springs across the contact radius at maximum load, a / spacing, and for
  an adhesive sphere on the elastic kernel across the JKR critical radius a_c, where its
  contact breaks (on the standard curve a_c = 0.86 a; an SI sphere of 1 mm at a_c / spacing
  1.5 gave twice JKR's pull-off, a 1 m one at 0.32 a pull-off of 0, without a word). The
  pull-off error was +3 % at 29 springs, +8 % at 14, +19 % at 7, +43 % at 3.6 and
  +65 % at 2.7 (about 1.3 spacing / a: inaccurate but meaningful), then +53 % at 1.8,
  +92 % at 1.3, +170 % at 0.9, -15 % at 0.67 and 0 when one spring touches: below 2
  the answer is erratic, set by which few springs touch.
- ``step``: loading steps max_indent / step. At spacing 1/32 the pull-off moved -16 %
  with 5 steps, -4 % with 10, -0.8 % with 50 and 0 with 200 against 400: below 10
  steps the step, not the physics, sets the answer. Under force control too, where
  ``step`` is the largest move of the flat while loading (tfm.protocol._load_to); the
  load steps max_load / load_step hardly matter, as the last load held is refined by
  bisection (jump-off at spacing 1/32 and 1/64: within 5e-5 and 3e-4 relative from 3 to
  400 load steps, 2026-11-24).
- ``tol``: the CG tolerance. Snap and entry decisions compare forces and gaps with the
  threshold, so a loose solve flips them, and a flipped decision moves the pull-off by a
  whole step: against tol 1e-10 on the standard curve (step 2.5e-4), tol 1e-4 moved it by
  +0.94 % at 1/64, +0.91 % at 1/128 and +0.56 % at 1/256 (+1.4 % with step 1e-3); 3e-5 by
  +0.56 % at 1/256; 1e-5 by at most 7.4e-7 and 1e-6 by at most 8.1e-8 from 1/32 to 1/256
  (also with step 1e-3; ``python -m bench.guards tol``, 2026-11-25, after the symbol's fix). Earlier, with step 1e-3 at 1/64 only, 1e-4
  had looked safe (3e-6), and 1e-4 was the limit until then.
- ``memory``: the estimate below against the memory the machine has available now.
- ``cost``: a direct-sum run whose estimated time (direct_cost_estimate, scaled from one
  measured curve) exceeds a week; a 1/2048 run was put at 80 years and started anyway,
  and a step of it does not end when a stop signal comes.
"""
from __future__ import annotations

import math

from .config import FIELD_BOX_FRACTIONS
from .params import LOOSE_THETA, ParameterError, Params

MIN_SPRINGS_ACROSS_RADIUS = 2.0
MIN_LOADING_STEPS = 10
MAX_TOL = 1e-6

# The half-space model treats the surface as flat on the scale of its heights' changes:
# beyond an rms slope of 1 (a mean inclination of 45 degrees) it does not describe the body,
# and a map that steep is more often heights and pixel in different units (heights written
# in micrometres over a pixel in metres are a million times too steep). Stated as a flag, not
# refused: nothing was measured to draw a line below it.
MAX_RMS_SLOPE = 1.0

# guard name -> the parameter it names and what it protects (``allow`` takes the names)
GUARDS = {
    "coarse": "spacing: fewer than 2 springs across the contact radius at maximum load, or across the "
              "JKR critical radius a_c of an adhesive sphere",
    "step": "step: fewer than 10 loading steps (step > max_indent / 10)",
    "tol": "tol: looser than 1e-6, so snap and entry decisions depend on the solver error",
    "memory": "spacing/extent: the estimated peak memory exceeds the memory available",
    "cost": "operator: a direct-sum run estimated to take more than a week",
}


class GuardError(ParameterError):
    """A valid record whose run would mean nothing (or not fit); ``allow`` overrides it.
    ``reason``: the message without the advice on how to override it."""

    reason: str = ""


def _below(x: float, limit: float, digits: int = 3) -> str:
    """x, for a message that says it is below ``limit``, with enough digits not to read
    as the limit itself (9.9999 steps printed as '10' under 'below 10')."""
    text = f"{x:.{digits}g}"
    while float(text) >= limit and digits < 17:
        digits += 1
        text = f"{x:.{digits}g}"
    return text


def _refuse(guard: str, message: str) -> None:
    exc = GuardError(f"{message}. To run it anyway, allow={guard!r} (CLI: --allow {guard}).")
    exc.reason = message
    raise exc


def _guard(notes: list, allowed: set, guard: str, message: str) -> None:
    """Refuse, or, where the guard is allowed, run with its reason as a note: stated before
    the run and kept among the summary's warnings (a flag), so a forced run is never taken
    for a clean one (an allowed coarse run was exit 0 with an empty warnings column)."""
    if guard not in allowed:
        _refuse(guard, message)
    notes.append(f"allowed past the {guard!r} guard: {message}")


def _breaks_at_critical_radius(p) -> bool:
    """An adhesive sphere or paraboloid on the elastic kernel: its contact breaks near the
    JKR critical radius a_c, which can be far smaller than the contact at the preload."""
    return p.kernel == "boussinesq" and p.shape in ("sphere", "paraboloid") and p.threshold_force > 0


def surface_rms_slope(p) -> float:
    """The rms slope of the body's roughness: ``rms_slope`` as given, that of the surface an
    ``rms_height`` makes, a height map's own (tfm.surfaces.map_rms_slope), and for a map
    with roughness added both in quadrature (independent slopes); 0 for a smooth body (its
    slopes are those of its radius). An rms_height of 0.032 at 1/64 made slopes of 1.15
    that were taken for 0."""
    slopes = []
    if p.shape == "height_map":
        from .surfaces import load_height_map, map_rms_slope
        slopes.append(map_rms_slope(p, load_height_map(p.height_map)))
    if p.rms_slope > 0 or p.rms_height > 0:
        from .surfaces import roughness_rms_slope
        slopes.append(roughness_rms_slope(p))
    return math.hypot(*slopes)          # in quadrature; a square would overflow for huge slopes


# ---- estimates (no NumPy needed: cheap enough for a million-run campaign) -----------
def contact_radius_estimate(p) -> float:
    """Contact radius at maximum load: the punch radius, Hertz sqrt(R d) for the elastic
    kernel, the geometric sqrt(2 R d) where the kernel is short-ranged (Winkler-like)."""
    if p.shape == "flat_punch":
        return p.radius
    if p.shape == "height_map":         # a nominally flat body as wide as the grid
        return p.half_width
    factor = 1.0 if p.kernel == "boussinesq" else 2.0
    return math.sqrt(factor * p.radius * p.delta_max)


def _coarse_remedy(p) -> str:
    """What refines a run too coarse for its contact. A height map's contact is the map:
    without its own pixel size the map's pixel is the spacing, and a finer spacing shrinks
    the map with it (the advice to refine it could not help, a user's hunt)."""
    if p.shape != "height_map":
        return "Refine the spacing or preload deeper"
    from .surfaces import load_height_map
    hm = load_height_map(p.height_map)
    nx, ny = hm.heights.shape
    if p.map_pixel_size is None and hm.pixel_size is None:
        return (f"The map has {nx} x {ny} pixels, each one spacing wide (no map_pixel_size given), so a finer "
                "spacing shrinks the map with it: use a larger map, or give map_pixel_size and refine the spacing")
    return f"Refine the spacing (the map has {nx} x {ny} pixels), or use a larger map"


def n_springs(p) -> int:
    """Springs of the layout (the geometry's own counting, without building it)."""
    hw = p.half_width
    if p.layout == "hexagonal":      # rows at r dy, |r| <= ceil(hw/dy); odd rows shifted by half
        rows = math.ceil(hw / (p.spacing * math.sqrt(3.0) / 2.0))
        even = 2 * (rows // 2) + 1
        h = (hw + 1e-12) / p.spacing
        return even * (2 * math.floor(h) + 1) + (2 * rows + 1 - even) * 2 * math.floor(h + 0.5)
    side = 2 * math.ceil(hw / p.spacing - 1e-9) + 1
    return side * side


def _next_fast_len(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n (scipy.fft.next_fast_len for real transforms, to
    within its extra factors 7 and 11, which only make it smaller)."""
    best = 2 * n
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


# bytes per spring and per padded FFT cell, and the runtime's own baseline; fitted to
# the peak resident memory measured at 513^2 and 1025^2 springs per operator (direct
# 164-185, tree 222 bytes a spring; the square grid's FFT symbol 16 bytes a cell), checked
# at 2049^2 (docs/physics.md, section 8). Since the FFT preconditioner keeps the inverse
# kernel in real space on the same box (8 bytes a cell, tfm.operators.FFTPreconditioner;
# its construction passes through the inverse symbol and complex transforms), the peak
# grew by 23 bytes a cell at 2049^2 (1059 -> 1485 MiB): 32.
BYTES_PER_SPRING = {"fft": 200.0, "direct": 200.0, "tree": 240.0}
BYTES_PER_FFT_CELL = 32.0
# the whole-grid field's smaller boxes (config.FIELD_BOX_FRACTIONS): one real symbol each,
# P x (P/2 + 1) doubles, 4 bytes a cell
BYTES_PER_FIELD_CELL = 4.0
# The tree operator's sparse neighbour list of the 'neighbors' kernel (building it holds
# pairs, distances, both directions and a sort order): 68 bytes per directed entry,
# measured at spacing 1/64 with 32 and 64 rings (769 and 1313 MiB peak), 2026-11-24.
BYTES_PER_NEIGHBOUR = 70.0
# field snapshots: three event candidates (F, u, state: 17 bytes each), the contact
# history and HDF5's chunk buffers; a user measured 57 bytes a spring more with
# --snapshots events (1/512, extent 1: 511 -> 569 MiB peak), 2026-11-25
BYTES_PER_SNAPSHOT_SPRING = 64.0
BASELINE_BYTES = 450e6     # measured 238 to 420 MiB after imports (and compilation)
# a height map is held as float64 for the whole run (tfm.surfaces: cached, checked and
# sampled without whole-map copies): a 6001^2 map at spacing 1/32 peaked at 495 MiB
# against 220 MiB for the same run from a 64^2 map, 8.0 bytes a pixel, 2026-11-25; 12
# with the transient mask of its check
BYTES_PER_MAP_PIXEL = 12.0


def estimate_memory(p) -> float:
    """Estimated peak resident memory of a run, in bytes.

    O(N) arrays per spring (positions, areas, heights, thresholds, forces, masks, the
    solver's work vectors; the tree's keys and nodes), plus for the FFT operator the
    full-grid symbol on the padded P x P box (P = fast size >= 2n - 1: the kernel, its
    real transform and the preconditioner's inverse kernel) and the symbols of the field's smaller boxes,
    plus the field snapshots' buffers, plus a height map's pixels, plus the
    Python/NumPy/SciPy/Numba runtime.
    """
    n = n_springs(p)
    total = BASELINE_BYTES + BYTES_PER_SPRING[p.operator_used] * n
    if p.layout == "square":          # the full-grid symbol is built for every kernel
        side = int(round(math.sqrt(n)))
        P = _next_fast_len(2 * side - 1)
        total += BYTES_PER_FFT_CELL * P * P
        rungs = {_next_fast_len(math.ceil(f * P)) for f in FIELD_BOX_FRACTIONS}
        total += BYTES_PER_FIELD_CELL * sum(Q * Q for Q in rungs if Q < P)
    if p.snapshots != "none":
        total += BYTES_PER_SNAPSHOT_SPRING * n
    if p.operator == "tree" and p.kernel == "neighbors":     # pi m^2 neighbours per spring
        total += BYTES_PER_NEIGHBOUR * n * min(n, math.pi * (p.neighbor_rings + 0.5) ** 2)
    if p.shape == "height_map":      # the map's own pixels (loaded already: cached)
        from .surfaces import load_height_map
        total += BYTES_PER_MAP_PIXEL * load_height_map(p.height_map).heights.size
    return total


def available_memory() -> float | None:
    """Bytes this process can still get (None if unknown): the machine's MemAvailable, and
    less where a limit applies, a control group's (SLURM, Docker, systemd) or ulimit -v. A
    job under such a limit passed the guard on the machine's figure and then died of a
    MemoryError mid-run."""
    rooms = []
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    rooms.append(float(line.split()[1]) * 1024.0)
    except OSError:
        pass
    rooms += _cgroup_rooms()
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            rooms.append(max(float(soft) - _status_bytes("VmSize:"), 0.0))
    except (ImportError, OSError, ValueError):
        pass
    return min(rooms) if rooms else None


_NO_LIMIT = 2.0 ** 60       # cgroup v1 writes "no limit" as a page-rounded 2**63 - 1


def _read_number(path: str) -> float | None:
    try:
        with open(path) as fh:
            text = fh.read().strip()
        return None if text == "max" else float(text)
    except (OSError, ValueError):
        return None


def _cgroup_rooms(proc: str = "/proc/self/cgroup", root: str = "/sys/fs/cgroup") -> list[float]:
    """limit - usage of this process's memory control group and of each group above it
    (cgroup v2 memory.max, v1 memory.limit_in_bytes), where a limit is set."""
    try:
        with open(proc) as fh:
            lines = fh.read().splitlines()
    except OSError:
        return []
    rooms = []
    for line in lines:
        hier, controllers, path = (line.split(":", 2) + ["", ""])[:3]
        if hier == "0" and controllers == "":
            base, limit, usage = root, "memory.max", "memory.current"
        elif "memory" in controllers.split(","):
            base, limit, usage = f"{root}/memory", "memory.limit_in_bytes", "memory.usage_in_bytes"
        else:
            continue
        parts = [q for q in path.split("/") if q]
        for k in range(len(parts), -1, -1):            # the group, then its parents
            folder = "/".join([base] + parts[:k])
            cap, used = _read_number(f"{folder}/{limit}"), _read_number(f"{folder}/{usage}")
            if cap is not None and cap < _NO_LIMIT and used is not None:
                rooms.append(max(cap - used, 0.0))
    return rooms


def _status_bytes(key: str) -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return float(line.split()[1]) * 1024.0
    return 0.0


# The direct sum's time, scaled from one measured curve (_direct_work): the standard curve
# (paraboloid R = 1, K_th 0.02, max_indent 0.05, step 2.5e-4) at spacing 1/256, 25,281
# springs, 338 s on the 2-core VM with 2 threads (1/128 took 8.5-25 s, 1/64 0.3-2.4 s on
# that noisy machine).
DIRECT_REFERENCE = dict(spacing=1 / 256, k_th=0.02, f_th=None, shape="paraboloid", max_indent=0.05,
                        step=2.5e-4, operator="direct")
DIRECT_REFERENCE_SECONDS = 338.0
COST_NOTE_SECONDS = 300.0           # a note above five minutes
COST_GUARD_SECONDS = 7 * 86400.0    # refused above a week (allow='cost')


def _duration(seconds: float) -> str:
    if seconds < 5400:
        return f"{seconds / 60:.0f} minutes"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.0f} hours"
    return f"{seconds / 86400:.0f} days"


def _direct_work(p) -> float:
    """What a direct-sum run's time grows with: its loading steps times (springs x springs
    in contact at maximum load)^1.25. Each CG iteration sums over the contact, each round's
    field over the grid times the contact, and the iterations grow as the contact refines:
    at a fixed geometry that is N^2.5, as measured from 1/64 to 1/256. The grid alone
    (N^2.5 whatever the contact) put a 1/128 run with extent 1 at an hour; it took a minute.
    Under force control the flat moves in steps of ``step`` and each load level adds its
    Newton solves: a load_step 50x finer took 15.6x the solves (1/48; the estimate had
    not moved)."""
    from .protocol import n_loading_steps

    n = n_springs(p)
    in_contact = min(n, max(1.0, math.pi * (contact_radius_estimate(p) / p.spacing) ** 2))
    steps = p.delta_max / p.step + (n_loading_steps(p) if p.control == "force" else 0)
    return steps * (n * in_contact) ** 1.25


def direct_cost_estimate(p) -> float | None:
    """Rough wall time of a direct-sum run in seconds (None for other operators and the
    local kernel, whose sum is a diagonal), scaled from DIRECT_REFERENCE."""
    if p.operator_used != "direct":
        return None
    return DIRECT_REFERENCE_SECONDS * _direct_work(p) / _direct_work(Params(**DIRECT_REFERENCE))


def _faster(p) -> str:
    return ("operator='fft' gives the same numbers (to 1e-12)" if p.layout == "square"
            else "operator='tree' is")


def direct_cost_note(p) -> str | None:
    """A note before a direct-sum run that would take more than a few minutes (a 1/512 run
    started without a word and would have taken hours), or None."""
    estimate = direct_cost_estimate(p)
    if estimate is None or estimate < COST_NOTE_SECONDS:
        return None
    ref = Params(**DIRECT_REFERENCE)
    return (f"operator='direct' sums every pair of springs: with {n_springs(p):,} springs expect roughly "
            f"{_duration(estimate)} on two cores (the standard curve at spacing 1/256, {n_springs(ref):,} "
            f"springs, took {DIRECT_REFERENCE_SECONDS / 60:.1f} minutes on a 2-core VM; the time grows about as "
            f"loading steps x (springs x springs in contact)^1.25); {_faster(p)} far faster")


def check_cost(p) -> list[str]:
    """The ``cost`` guard: refuse (GuardError) a direct-sum run estimated at more than
    COST_GUARD_SECONDS unless allowed; its note if allowed. The estimate is this VM's, so
    campaign files are not checked with it; a campaign checks it when it starts."""
    took = direct_cost_estimate(p)
    if took is None or took <= COST_GUARD_SECONDS:
        return []
    notes: list[str] = []
    _guard(notes, _allowed(p), "cost", f"operator: the direct sum over {n_springs(p):,} springs would take "
           f"roughly {_duration(took)} (scaled from the standard curve at spacing 1/256, "
           f"{DIRECT_REFERENCE_SECONDS / 60:.1f} minutes on a 2-core VM); {_faster(p)} far faster")
    return notes


def contact_reached_note(p, max_n_contact: int) -> str | None:
    """After a run: the ``coarse`` guard on the contact the run reached (the estimate
    before it assumes a smooth body: a rough one can touch at a few springs only). The
    contact's equivalent radius sqrt(n / pi) spacings, against the same threshold."""
    across = math.sqrt(max_n_contact / math.pi)
    if across >= MIN_SPRINGS_ACROSS_RADIUS or "coarse" in _allowed(p):
        return None
    return (f"at most {max_n_contact} springs were in contact (as many as a disc of radius "
            f"{_below(across, MIN_SPRINGS_ACROSS_RADIUS, 2)} "
            f"spacings); below {MIN_SPRINGS_ACROSS_RADIUS:g} the pull-off is erratic: refine the spacing or "
            "preload deeper (allow='coarse' accepts it)")


def kernel_check_key(p) -> tuple | None:
    """What tfm.operators.check_record's answer depends on. None: nothing to check, a
    local kernel or the default one on the square grid (its smallest symbol is 0.89 /
    spacing from 15^2 to 513^2 springs, measured 2026-11-24). On the square grid C is a
    function of r / spacing times 1 / spacing, so only the kernel and the grid's size
    matter; other layouts depend on the positions themselves."""
    if p.kernel == "local":
        return None                                   # a positive diagonal
    kernel = (p.kernel, p.self_term, p.neighbor_rings if p.kernel == "neighbors" else None)
    if p.layout == "square":
        if p.kernel == "boussinesq" and p.self_term == Params.self_term:   # the field's default
            return None
        return (*kernel, "square", math.ceil(p.half_width / p.spacing - 1e-9))
    return (*kernel, p.layout, p.jitter, p.seed, p.spacing, p.half_width)


def _allowed(p) -> set[str]:
    return set(filter(None, p.allow.split(",")))


def check(p, memory: bool = True) -> list[str]:
    """Refuse a meaningless or oversized run (GuardError) unless allowed; return the
    notes to state before it starts. ``memory=False`` skips the machine-dependent part
    (campaign files are validated on one machine and may run on another)."""
    from .units import to_paper, unit_suffixes
    metres, newtons = unit_suffixes(p)
    given_load = p.max_load             # as the user gave it (newtons for SI), for the messages
    p = to_paper(p)                     # SI: the same lengths, forces in the paper's units
    allowed = _allowed(p)
    notes = []
    a = contact_radius_estimate(p)
    across = a / p.spacing
    if across < MIN_SPRINGS_ACROSS_RADIUS:
        _guard(notes, allowed, "coarse", f"spacing: only {_below(across, MIN_SPRINGS_ACROSS_RADIUS, 2)} springs across the "
                          "contact radius at maximum "
                          f"load (a ~ {a:.3g}, spacing {p.spacing:.3g}); below "
                          f"{MIN_SPRINGS_ACROSS_RADIUS:g} the pull-off is erratic (errors of 50 to 170 %; "
                          "one touching spring gives a pull-off of 0). " + _coarse_remedy(p))
    elif _breaks_at_critical_radius(p):
        from .theory import run_critical_radius
        a_c = run_critical_radius(p)
        across = a_c / p.spacing
        if across < MIN_SPRINGS_ACROSS_RADIUS:
            _guard(notes, allowed, "coarse", f"spacing: only {_below(across, MIN_SPRINGS_ACROSS_RADIUS, 2)} springs "
                   f"across the JKR critical radius a_c = {a_c:.3g}{metres}, where the contact breaks "
                   f"(spacing {p.spacing:.3g}); below {MIN_SPRINGS_ACROSS_RADIUS:g} the pull-off is erratic "
                   "(1.5 springs: twice JKR's; 0.32: a pull-off of 0, one spring's threshold above JKR's "
                   "whole force). Refine the spacing")
    # An automatic preload is never shallower than 10 steps, so against it a coarse step
    # could never be refused; it is measured against the depth the physics asks for (1/64,
    # step 0.05: the preload went 6x deeper, pull-off -17 %). A flat punch's pull-off does
    # not depend on its preload.
    # Under force control with a max_load the depth is that load's non-adhesive one.
    auto = (p.max_indent == "auto" and p.shape != "flat_punch"
            and not (p.control == "force" and p.max_load is not None))
    depth = p.delta_max
    if auto:
        from .theory import auto_max_indent
        depth = auto_max_indent(p, step_floor=False)
    steps = depth / p.step
    if steps < MIN_LOADING_STEPS * (1 - 1e-9):
        # under force control max_indent follows max_load: name what the user gave
        where = ("the automatic preload depth" if auto else f"the depth of max_load {given_load:g}{newtons}:"
                 if p.control == "force" and p.max_load is not None else "max_indent")
        _guard(notes, allowed, "step", f"step: only {_below(steps, MIN_LOADING_STEPS)} loading steps to {where} "
                        f"{depth:.3g}{metres} (step {p.step:.3g}{metres}); "
                        f"below {MIN_LOADING_STEPS} the step shifts the pull-off by up to 16 %. Use step <= "
                        f"{depth / MIN_LOADING_STEPS:.3g}{metres}" + (", or give max_indent" if auto else ""))
    if p.tol > MAX_TOL:
        _guard(notes, allowed, "tol", f"tol: {p.tol:g} is looser than {MAX_TOL:g}; snap and entry decisions then "
                       "follow the solver error and can move the pull-off by a whole step (tol 1e-4: +0.94 % at "
                       "spacing 1/64, +0.91 % at 1/128; 3e-5: +0.56 % at 1/256; 1e-2: -41 % at 1/128)")
    if memory:
        need, have = estimate_memory(p), available_memory()
        if have is not None and need > have:
            _guard(notes, allowed, "memory", f"spacing/extent: the run needs about {need / 2**30:.1f} GiB "
                              f"({n_springs(p):,} springs, operator {p.operator}) but "
                              f"{have / 2**30:.1f} GiB is available. Coarsen the spacing or shrink extent")
        notes += check_cost(p)
    if p.operator == "tree" and p.kernel == "boussinesq" and p.theta > LOOSE_THETA:
        from .tree_operator import tree_error_bound
        # percentages with 3 digits: at theta 1 the bound is 1.03, which .2g called "1"
        notes.append(f"theta: {p.theta:g} is loose: the tree's error bound is {100 * tree_error_bound(p.theta):.3g} % "
                     f"of sum |f|/r at each target ({100 * tree_error_bound(0.5):.2g} % at 0.5), and snap decisions follow "
                     "it (theta 1 against the direct sum, spacing 1/48: the pull-off indent 18 steps off); "
                     f"theta <= {LOOSE_THETA:g} kept the pull-off within 5e-6")
    slope = surface_rms_slope(p)
    if not slope <= MAX_RMS_SLOPE:          # NaN too: heights beyond what a float can square
        is_map = p.shape == "height_map"
        if is_map:
            whose = "height_map and roughness: their combined" if p.rms_slope > 0 or p.rms_height > 0 \
                else "height_map: the map's"
        elif p.rms_slope > 0:
            whose = "rms_slope: the requested"
        else:
            whose = f"rms_height: the {p.rms_height:g} rms height surface's"
        notes.append(f"{whose} rms slope is {slope:.3g}, steeper than {MAX_RMS_SLOPE:g} (45 degrees): the half-space "
                     "(Boussinesq) model assumes gentle slopes"
                     + (" -- are the heights and the pixel size in the same length unit?" if is_map else ""))
    if p.shape == "paraboloid" and p.delta_max > p.radius:
        # a sphere deeper than R is refused by its geometry; a paraboloid is not, and an SI
        # run given the paper's max_indent 0.05 for R = 1 mm started a 50 R preload
        notes.append(f"max_indent: {p.delta_max:g}{metres} is deeper than the paraboloid's radius {p.radius:g}{metres}: "
                     f"its slope at the Hertz contact edge, sqrt(max_indent/R) = {math.sqrt(p.delta_max / p.radius):.3g}, "
                     f"is steeper than {MAX_RMS_SLOPE:g} (45 degrees), where the half-space model assumes gentle "
                     "slopes" + (" -- paper-unit values mixed into an SI run?" if metres else ""))
    # a flat punch is in full contact at any depth: its pull-off does not depend on the preload.
    # An explicit max_load is the user's preload, as an explicit max_indent is (not flagged:
    # at 1/32 a max_load of 0.004, depth 0.045 where the estimate asks 0.082, gave a jump-off
    # of 0.00383539 against 0.00383539 from the estimate's depth, 2026-11-25)
    explicit_load = p.control == "force" and p.max_load is not None
    if p.max_indent == "auto" and p.shape != "flat_punch" and not explicit_load:
        from .protocol import n_loading_steps
        from .theory import auto_max_indent_uncapped, auto_preload_basis

        wanted = auto_max_indent_uncapped(p)
        if wanted > p.delta_max * (1 + 1e-12):
            notes.append(f"max_indent: auto preload capped at 0.5 R = {p.delta_max:.4g}{metres} "
                         f"({auto_preload_basis(p)} asks for {wanted:.4g}{metres}); the "
                         f"preload may be too shallow for the pull-off; {n_loading_steps(p)} loading steps")
    return notes
