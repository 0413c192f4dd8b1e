"""One frozen, validated parameter record per run, named after the paper's symbols.

Hulikal, Bhattacharya & Lapusta, "A threshold-force model for adhesion and mode I
fracture" (docs/physics.md). Everything is in the paper's nondimensional units:
length L*, force F* = 2 pi G L*^2 / (1 - nu), so C_ij = 1/r_ij.

The record's hash (with the result schema version) is the run id, so two runs with the
same parameters are the same run. Bad values fail at construction with a message that
names the parameter and the allowed range.

Every parameter is used or refused: ``APPLIES`` (below) says, in one place, when each
conditional parameter has an effect. A non-default value where it has none is a
ParameterError; a default value given explicitly there (a CLI flag, a campaign key) is a
named ParameterWarning. ``allow`` is the one field that is not hashed into the run id: it
overrides the meaningful-run guards of ``tfm.guards`` and does not change any number.
"""
from __future__ import annotations

import dataclasses
import decimal
import difflib
import functools
import hashlib
import json
import math
import numbers
import os
import re
import warnings
from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping

from .config import SCHEMA_VERSION

SHAPES = ("sphere", "paraboloid", "flat_punch", "height_map")
KERNELS = ("boussinesq", "local", "neighbors")
OPERATORS = ("fft", "direct", "tree")
LAYOUTS = ("square", "hexagonal", "jittered")
SNAP_RULES = ("batch", "single")
PRECONDITIONERS = ("auto", "fft", "stencil", "diagonal", "none")
CONTROLS = ("displacement", "force")
SNAPSHOT_MODES = ("none", "events")
DISORDERS = ("none", "uniform", "weibull")
UNITS = ("paper", "si")

#: the text-valued fields and their values; loose input (the command line, TOML, from_dict)
#: is read case-blind against these, the record itself holds them as written here
CHOICES: dict[str, tuple[str, ...]] = {
    "shape": SHAPES, "kernel": KERNELS, "operator": OPERATORS, "layout": LAYOUTS,
    "snap_rule": SNAP_RULES, "preconditioner": PRECONDITIONERS, "control": CONTROLS,
    "threshold_disorder": DISORDERS, "units": UNITS,
}


class ParameterError(ValueError):
    """A run parameter is missing, malformed or outside its allowed range."""


class InapplicableError(ParameterError):
    """A non-default value of a parameter that has no effect in this run (APPLIES);
    ``name`` is the parameter (a campaign's [base] key may apply in some runs only)."""

    def __init__(self, message: str, name: str):
        super().__init__(message)
        self.name = name


class ParameterWarning(UserWarning):
    """A parameter was given where it has no effect (its default value, so harmless)."""


_DECIMAL = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_FRACTION = re.compile(rf"^\s*({_DECIMAL})\s*/\s*({_DECIMAL})\s*$")


def parse_number(value: Any, name: str) -> float:
    """Accept numbers (NumPy scalars too) and strings such as ``"2e-5"`` or ``"1/64"``.

    A fraction is exactly two decimal numbers around one slash: "1//64", "1/6/4" and
    "1/" are refused, never read as some other number."""
    if isinstance(value, bool) or (type(value).__module__ == "numpy" and "bool" in type(value).__name__):
        raise ParameterError(f"{name}: expected a number, got a boolean {value!r}")
    if isinstance(value, numbers.Real):
        return _plain_float(value)
    if isinstance(value, str):
        text = value.strip()
        match = _FRACTION.match(text)
        if match:                       # both parts match _DECIMAL, so float() reads them
            num, den = (float(g) for g in match.groups())
            if den == 0.0:
                raise ParameterError(f"{name}: cannot read {value!r} as a number (division by zero)")
            return num / den
        try:
            if "/" not in text and "_" not in text:
                return float(text)
        except ValueError:
            pass
    raise ParameterError(f"{name}: cannot read {value!r} as a number (use e.g. 0.5, 2e-5 or 1/64)")


def _plain_float(value: numbers.Real) -> float:
    """A Python float; a NumPy float of less than double precision as the number it
    prints (np.float32(0.1) is 0.1 as meant, not 0.10000000149...: one run, not two)."""
    dtype = getattr(value, "dtype", None)
    if dtype is not None and dtype.kind == "f" and dtype.itemsize < 8:
        return float(str(value))
    return float(value)


@dataclass(frozen=True)
class Params:
    """Parameters of one loading-unloading run (the paper's symbols).

    Threshold: ``f_th = k_th * A**alpha`` with A the spring's area (spacing**2 on the
    square grid), unless an explicit ``f_th`` is given (then ``k_th`` must be None).
    """

    # discretization and threshold
    spacing: float = 1.0 / 128          # Delta
    alpha: float = 0.75                 # threshold exponent
    k_th: float | None = None           # K_th
    f_th: float | None = 2e-5           # explicit F_th (paper's Fig. 3 default)
    # geometry
    radius: float = 1.0                 # R
    shape: str = "sphere"
    # interaction kernel
    kernel: str = "boussinesq"
    self_term: float = 3.8              # C_ii = self_term / spacing (Love's regularization)
    neighbor_rings: int = 1             # m, kernel="neighbors": keep 1/r for r <= m*spacing
    c_w: float = 1.0                    # kernel="local": C_ii = c_w / A (Winkler)
    # numerics
    operator: str = "fft"
    theta: float = 0.5                  # Barnes-Hut opening angle (operator="tree")
    layout: str = "square"
    jitter: float = 0.25                # layout="jittered": offsets in units of spacing
    seed: int = 0                       # layout="jittered"
    # loading protocol: load to max_indent in steps of `step`, unload until no contact
    max_indent: float | str = "auto"    # delta_max, or "auto": deep enough for the JKR pull-off
    step: float = 2.5e-4
    snap_rule: str = "batch"            # paper: all violators change at once
    # solver
    tol: float = 1e-10                  # relative residual of the contact solve
    max_iter: int = 2000                # CG iterations per solve
    max_rounds: int = 10000             # snap/enter rounds per step
    max_unload_steps: int | None = None  # None: tfm.protocol.default_max_unload_steps
    preconditioner: str = "auto"
    # grid extent (half-width of the square region holding the springs); None = auto
    extent: float | None = None
    extent_margin: float = 1.3          # auto extent = margin * Hertz radius + 4 spacings
    # self-affine roughness added to the shape (tfm.surfaces; SurfaceTopography's
    # fourier_synthesis conventions). rms_slope = rms_height = 0: smooth.
    hurst: float = 0.8                  # H in (0, 1): C(q) ~ q^(-2-2H)
    rms_slope: float = 0.0              # spectral rms slope of the realized surface
    rms_height: float = 0.0             # or its rms height (give one of the two)
    short_cutoff: float | None = None   # lambda_s; None = 4 spacings
    long_cutoff: float | None = None    # lambda_L; None = the grid side (no roll-off)
    rolloff: float = 1.0                # PSD at q < q_L (longer than long_cutoff) = rolloff^2 C(q_L)
    roughness_seed: int = 0
    # measured topography: shape="height_map"
    height_map: str | None = None       # path to a .npy (or, with tfm[topography], any
                                        # format SurfaceTopography reads); heights in length units
    map_pixel_size: float | None = None  # None = spacing
    height_map_hash: str | None = None  # sha256 of the map's heights; filled in, then checked
    # per-spring threshold disorder around the mean F_th (tfm.threshold)
    threshold_disorder: str = "none"    # none | uniform | weibull
    disorder_width: float = 0.0         # coefficient of variation std(F_th)/mean(F_th)
    disorder_seed: int = 0
    # physical units (tfm.units); "si": lengths in m, forces in N
    units: str = "paper"
    youngs_modulus: float | None = None   # E (Pa), units="si"
    poisson_ratio: float | None = None    # nu in (-1, 0.5], units="si"
    work_of_adhesion: float | None = None  # gamma (J/m^2), units="si"
    k_th_coefficient: float | str = "paper"  # c in F_max = c K_th^2 R: a number or a name
    # loading protocol (tfm.protocol) and field output (tfm.snapshots)
    control: str = "displacement"       # "displacement" (the paper's runs) or "force"
    max_load: float | None = None       # control="force": peak compressive load; None = Hertz load at max_indent
    load_step: float | None = None      # control="force": load decrement; None = max_load / 100
    snapshots: int | str = "none"       # "none", "events", or every k-th step (plus the events)

    # meaningful-run guards to override (tfm.guards.GUARDS), comma-separated; not hashed
    allow: str = ""

    def __post_init__(self) -> None:
        if self.threshold_disorder is None:       # "none" in TOML and on the CLI reads as None
            object.__setattr__(self, "threshold_disorder", "none")
        _normalize(self)
        _validate_protocol(self)       # before _validate: delta_max may depend on max_load
        _validate(self)
        _validate_protocol_relations(self)

    # ---- derived quantities -------------------------------------------------
    @property
    def threshold_force(self) -> float:
        """Mean F_th of one spring of the layout (formula: ``tfm.threshold``)."""
        from .threshold import mean_threshold
        return mean_threshold(self)

    @property
    def peak_load(self) -> float:
        """control="force": the peak compressive load, resolving ``max_load=None`` to the
        Hertz load at ``delta_max``."""
        if self.max_load is not None:
            return float(self.max_load)
        from .theory import preload_force
        from .units import force_scale           # theory is in paper units (SI: L* = 1 m)
        return float(preload_force(self.shape, self.delta_max, self.radius)) * force_scale(self)

    @property
    def operator_used(self) -> str:
        """The operator that computes C F: ``operator``, except for the local kernel, a
        diagonal, which takes the tree operator's neighbour-list path with no neighbours
        (O(N) on any layout; ``operator`` does not apply there)."""
        return "tree" if self.kernel == "local" else self.operator

    @property
    def load_decrement(self) -> float:
        """control="force": the load step, resolving ``load_step=None``."""
        return float(self.load_step) if self.load_step is not None else self.peak_load / 100.0

    @functools.cached_property           # a pure function of a frozen record
    def delta_max(self) -> float:
        """The preload depth, resolving ``max_indent="auto"`` (under force control with an
        explicit max_load: the non-adhesive depth of that load, Hertz or the flat punch's,
        which sizes the grid)."""
        if (self.max_indent == "auto" and getattr(self, "max_load", None) is not None
                and self.control == "force"):        # elsewhere max_load is refused, not used
            from .theory import preload_indent
            from .units import force_scale      # theory is in paper units (SI: L* = 1 m)
            load = self.max_load / force_scale(self) if self.units == "si" else self.max_load
            return float(preload_indent(self.shape, load, self.radius))
        if self.max_indent == "auto" and self.units == "si":
            from .theory import AUTO_PRELOAD_CAP, auto_max_indent
            from .units import to_paper     # same lengths in paper units with L* = 1 m
            # The twin carries no load_step or max_load (the preload does not depend on
            # them here) and a step that passes its checks: this record checks its own
            # loads and step, in newtons and metres, and the step only floors the depth.
            twin = to_paper(self, load_step=None, max_load=None, step=AUTO_PRELOAD_CAP * self.radius / 10)
            return auto_max_indent(twin, step=self.step)
        if self.max_indent == "auto":
            from .theory import auto_max_indent
            try:
                return auto_max_indent(self)
            except OverflowError:       # K_IC^2 or R^2 beyond floats (a fuzzed k_th of 1.3e154)
                raise ParameterError(f"max_indent: the automatic preload overflows for F_th = "
                                     f"{self.threshold_force:.3g} and radius {self.radius:.3g}; give max_indent, or "
                                     "a threshold (k_th, f_th) and radius of a size a float can square") from None
        return float(self.max_indent)

    @property
    def half_width(self) -> float:
        if self.extent is not None:
            return float(self.extent)
        if self.shape == "height_map":      # the largest centred square the map covers
            from .surfaces import load_height_map, map_half_width
            return map_half_width(self, load_height_map(self.height_map))
        # Hertz radius for the elastic kernel; the geometric one where the kernel is
        # short-ranged (Winkler-like) and the contact spreads further.
        factor = 1.0 if self.kernel == "boussinesq" else 2.0
        a_max = math.sqrt(factor * self.radius * self.delta_max)
        if self.shape == "flat_punch":
            a_max = self.radius
        return self.extent_margin * a_max + 4.0 * self.spacing

    # ---- (de)serialization ------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in _NAMES}    # scalars and strings only

    def canonical_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    @functools.cached_property
    def run_id(self) -> str:
        """Hash of the parameters that change the numbers (all but ``NOT_HASHED``)."""
        # fields added after the first schema are left out at their defaults, so runs
        # stored before they existed keep their ids
        values = {k: v for k, v in self.to_dict().items() if k not in NOT_HASHED
                  and not (k in _LATER_FIELDS and v == _LATER_FIELDS[k])}
        text = f"schema={SCHEMA_VERSION};" + json.dumps(values, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_dict(cls, values: Mapping[str, Any], *, where: str = "", advise: bool = True) -> "Params":
        """Build from loose input (CLI, TOML): fractions accepted, unknown keys refused.
        The keys given are checked by ``advise`` (not with ``advise=False``, nor for a
        complete record: a stored one, read back)."""
        names = cls.field_names()
        prefix = f"{where}: " if where else ""
        clean: dict[str, Any] = {}
        for key, value in values.items():
            clean[key] = parse_param(key, value, where)
        # an explicit k_th without f_th means "use k_th"; so does an SI run (its threshold
        # follows from work_of_adhesion, and the default f_th is in paper units)
        if (clean.get("k_th") is not None or clean.get("units") == "si") and "f_th" not in clean:
            clean["f_th"] = None
        try:
            params = cls(**clean)
        except InapplicableError as exc:
            raise InapplicableError(f"{prefix}{exc}", exc.name) from None
        except ParameterError as exc:
            raise ParameterError(f"{prefix}{exc}") from None
        # a complete record (a stored one, read back) carries every default: no warnings
        if advise:
            params.advise(clean if set(clean) != set(names) else {}, prefix)
        return params

    @classmethod
    def from_row(cls, row: Mapping[str, Any], prefix: str = "p_") -> "Params":
        """Rebuild the record from a table row (summary, failures, ``tfm campaign expand
        --json``): the ``<prefix><name>`` columns, where a missing value (NaN, NA) of an
        optional parameter is None. A row without such columns but with the bare names
        (``expand --json``) is read by those. A row with a ``run_id`` must give that run
        back: a row short of a column rebuilt another run at that column's default, silently."""
        names = cls.field_names()
        if prefix and not any(prefix + n in row for n in names) and any(n in row for n in names):
            prefix = ""
        values = {}
        for name in names:
            if prefix + name not in row:
                continue
            value = row[prefix + name]
            if _is_missing(value) and name in _OPTIONAL:
                value = None
            values[name] = value
        params = cls.from_dict(values, where="table row")
        stored = row["run_id"] if "run_id" in row else None
        if isinstance(stored, str) and params.run_id != stored:
            absent = [prefix + n for n in names if n not in values and n not in NOT_HASHED]
            why = (f"; the row has no column {', '.join(absent[:5])}{', ...' if len(absent) > 5 else ''}"
                   if absent else "; its values do not make that run (another tfm schema, or a changed "
                                  "height map?)")
            raise ParameterError(f"table row: its run_id is {stored}, but its parameters make run "
                                 f"{params.run_id}{why}")
        return params

    def advise(self, given: Mapping[str, Any], prefix: str = "", stacklevel: int = 2) -> None:
        """Warn (ParameterWarning) about the parameters in ``given`` (name -> value as
        given) that have no effect on this record, and a map without a pixel size (a loose
        tree is a note of the run: tfm.guards.check). Once per record: Params.from_dict and
        replace advise on what they were given, and tfm.simulate advises a record built
        otherwise on its fields off their defaults. ``stacklevel`` as warnings.warn's, seen
        from the caller of advise."""
        object.__setattr__(self, "_advised", True)      # not a field: not compared, hashed or stored
        stacklevel += 1
        for name in given:
            rule = APPLIES.get(name)
            if rule is not None and not rule.applies(self) and not rule.also(self):
                warnings.warn(f"{prefix}{name}: given but has no effect; it applies only when {rule.when}",
                              ParameterWarning, stacklevel=stacklevel)
        for name, why in _moot(self):
            if name in given and given[name] != _DEFAULTS[name]:
                warnings.warn(f"{prefix}{name}: given but has no effect here: {why}", ParameterWarning,
                              stacklevel=stacklevel)
        # a map without a pixel size is drawn at the spacing: a new map, or a new spacing,
        # makes another body
        if (("height_map" in given or "spacing" in given) and "map_pixel_size" not in given
                and self.shape == "height_map" and self.map_pixel_size is None):
            from .surfaces import load_height_map
            if load_height_map(self.height_map).pixel_size is None:
                kind = os.path.splitext(str(self.height_map))[1] or "bare"      # .npy, .npz, .txt: no pixel size
                warnings.warn(f"{prefix}map_pixel_size: not given, and the map carries none (a {kind} file): its pixel is "
                              f"the spacing ({self.spacing:g}), so at another spacing it is another body, "
                              "scaled with it; give map_pixel_size to fix its size", ParameterWarning,
                              stacklevel=stacklevel)

    def replace(self, **changes: Any) -> "Params":
        """A copy with ``changes``, read like from_dict (fractions, "none"); one of
        k_th and f_th given clears the other, and so does units = "si" the paper-units f_th.
        The changes are advised on (``advise``) if this record was."""
        new = self._replaced(changes)
        if getattr(self, "_advised", False):
            # None for an optional parameter clears it (max_load=None on leaving force
            # control): a change back to its default is no parameter given
            new.advise({key: getattr(new, key) for key in changes
                        if not (changes[key] is None and _DEFAULTS[key] is None)})
        return new

    def _replaced(self, changes: Mapping[str, Any]) -> "Params":
        """replace without the advice."""
        changes = {key: parse_param(key, value) for key, value in changes.items()}
        if (changes.get("k_th") is not None or changes.get("units") == "si") and "f_th" not in changes:
            changes["f_th"] = None
        if changes.get("f_th") is not None and "k_th" not in changes:
            changes["k_th"] = None
        if "height_map" in changes and "height_map_hash" not in changes:
            changes["height_map_hash"] = None        # a new map: hash its content again
        return dataclasses.replace(self, **changes)


# fields added after schema 1, with their defaults (left out of the run id at default)
_LATER_FIELDS = {f.name: f.default for f in fields(Params)
                 if f.name in ("hurst", "rms_slope", "rms_height", "short_cutoff", "long_cutoff",
                               "rolloff", "roughness_seed", "height_map", "map_pixel_size",
                               "height_map_hash", "threshold_disorder", "disorder_width",
                               "disorder_seed", "units", "youngs_modulus", "poisson_ratio",
                               "work_of_adhesion", "k_th_coefficient",
                               "control", "max_load", "load_step", "snapshots")}


# fields that change no number, so not part of the run id: ``allow``; the map's path
# (the map enters through height_map_hash, its content: the same heights under another
# path or name are the same run)
NOT_HASHED = ("allow", "height_map")


def _kind(annotation: str) -> str:
    """float, int or str, from a field's annotation (a new field needs no list here)."""
    return "float" if "float" in annotation else "int" if "int" in annotation else "str"


_NAMES = tuple(f.name for f in fields(Params))
_KINDS = {f.name: _kind(str(f.type)) for f in fields(Params)}
_OPTIONAL = {f.name for f in fields(Params) if "None" in str(f.type)}
_DEFAULTS = {f.name: f.default for f in fields(Params)}


def _is_missing(value: Any) -> bool:
    if value is None:
        return True
    if isinstance(value, float) and math.isnan(value):
        return True
    return type(value).__name__ in ("NAType", "NaTType")


def _normalize(p: Params) -> None:
    """NumPy scalars and ints in float fields become plain Python numbers, and -0.0
    becomes 0.0, so equal records have equal run ids (``radius=1`` and
    ``radius=np.float64(1.0)``; ``k_th = [0.0, -0.0]`` made two runs of one)."""
    for name, kind in _KINDS.items():
        value = getattr(p, name)
        t = type(value)
        if t is float:
            if value == 0.0:
                object.__setattr__(p, name, 0.0)
            continue
        if t is str or t is bool or value is None:
            continue                                   # the common case, kept cheap
        if t is int:
            if kind == "float":
                object.__setattr__(p, name, float(value))
        elif kind == "float" and isinstance(value, numbers.Real):
            object.__setattr__(p, name, _plain_float(value) + 0.0)       # + 0.0: -0.0 -> 0.0
        elif kind == "int" and isinstance(value, numbers.Integral):
            object.__setattr__(p, name, int(value))
    if isinstance(p.allow, str):
        names = sorted({a.strip() for a in p.allow.split(",") if a.strip()})
        object.__setattr__(p, "allow", ",".join(names))
    if isinstance(p.height_map, (str, os.PathLike)) and str(p.height_map):
        # absolute: a stored record finds its map from any working directory
        object.__setattr__(p, "height_map", os.path.abspath(os.path.expanduser(str(p.height_map))))


def _rough(p: Params) -> bool:
    return p.rms_slope > 0 or p.rms_height > 0


# ---- which parameters apply when: the one table ----------------------------------
@dataclass(frozen=True)
class Applies:
    """When a conditional parameter has an effect. ``also`` lists values accepted where
    it has none because they state the truth (alpha = 0 with an explicit f_th)."""

    when: str
    test: Callable[[Params], bool]
    also: Callable[[Params], bool] = lambda p: False

    def applies(self, p: Params) -> bool:
        return self.test(p)


# Policy: a non-default value where the parameter has no effect is a ParameterError; the
# default value given explicitly there is a ParameterWarning (harmless, but probably not
# what was meant). New conditional parameters add one line here.
APPLIES: dict[str, Applies] = {
    # with work_of_adhesion (SI), F_th = K_th A^alpha too, its K_th derived for alpha = 0.75
    "alpha": Applies("k_th or work_of_adhesion is given (F_th = K_th A^alpha); with f_th, alpha = 0 "
                     "(no area dependence) is accepted too",
                     lambda p: p.k_th is not None or (p.units == "si" and p.work_of_adhesion is not None),
                     also=lambda p: p.alpha == 0.0),
    "self_term": Applies("kernel is 'boussinesq' or 'neighbors' (the Winkler kernel uses c_w)",
                         lambda p: p.kernel != "local"),
    "neighbor_rings": Applies("kernel='neighbors'", lambda p: p.kernel == "neighbors"),
    "c_w": Applies("kernel='local'", lambda p: p.kernel == "local"),
    # the tree serves the long-range kernel only (local and neighbors sums are exact)
    "theta": Applies("operator='tree' and kernel='boussinesq'",
                     lambda p: p.operator == "tree" and p.kernel == "boussinesq"),
    # the Winkler kernel is a diagonal: no sum for an operator to compute (Params.operator_used)
    "operator": Applies("kernel is 'boussinesq' or 'neighbors' (the local kernel is a diagonal, "
                        "computed alike on every layout)", lambda p: p.kernel != "local"),
    "jitter": Applies("layout='jittered'", lambda p: p.layout == "jittered"),
    "seed": Applies("layout='jittered'", lambda p: p.layout == "jittered"),
    "max_load": Applies("control='force'", lambda p: p.control == "force"),
    "load_step": Applies("control='force'", lambda p: p.control == "force"),
    "extent_margin": Applies("extent is automatic (extent = none) and shape is not 'height_map'",
                             lambda p: p.extent is None and p.shape != "height_map"),
    # roughness, height maps, threshold disorder, units (tfm.surfaces, tfm.threshold, tfm.units)
    **{name: Applies("the surface is rough (rms_slope or rms_height > 0)", lambda p: _rough(p))
       for name in ("hurst", "short_cutoff", "long_cutoff", "roughness_seed")},
    "rolloff": Applies("the surface is rough and long_cutoff is given (rolloff sets the PSD below it)",
                       lambda p: _rough(p) and p.long_cutoff is not None),
    "radius": Applies("shape is 'sphere', 'paraboloid' or 'flat_punch'", lambda p: p.shape != "height_map"),
    **{name: Applies("shape='height_map'", lambda p: p.shape == "height_map")
       for name in ("height_map", "map_pixel_size", "height_map_hash")},
    **{name: Applies("threshold_disorder is 'uniform' or 'weibull'", lambda p: p.threshold_disorder != "none")
       for name in ("disorder_width", "disorder_seed")},
    **{name: Applies("units='si' (paper units have E* = 1/pi)", lambda p: p.units == "si")
       for name in ("youngs_modulus", "poisson_ratio", "work_of_adhesion")},
    "k_th_coefficient": Applies("units='si' and work_of_adhesion is given",
                                lambda p: p.units == "si" and p.work_of_adhesion is not None),
}


def _moot(p: Params) -> list[tuple[str, str]]:
    """Parameters that apply but whose values change nothing in this run: with every
    threshold zero, the exponent and the disorder around it; with jitter 0, the seed of the
    jitter. Warned about (from_dict), not refused: a campaign may sweep k_th or jitter
    through 0 with the rest fixed."""
    moot = []
    if p.layout == "jittered" and p.jitter == 0:
        moot.append(("seed", "jitter is 0, so the jittered layout is the square grid whatever the seed"))
    zero = p.f_th == 0 or (p.f_th is None and p.k_th == 0) or (p.units == "si" and p.work_of_adhesion == 0)
    if zero:
        why = "every threshold is zero (no adhesion)"
        # with an explicit f_th, alpha already applies only as 0 (APPLIES)
        names = (["alpha"] if p.f_th is None else []) + (["threshold_disorder", "disorder_width", "disorder_seed"]
                                                          if p.threshold_disorder != "none" else [])
        moot += [(name, why) for name in names]
    return moot


def _check_applies(p: Params) -> None:
    for name, rule in APPLIES.items():
        value = getattr(p, name)
        if rule.applies(p) or value == _DEFAULTS[name] or rule.also(p):
            continue
        raise InapplicableError(f"{name}: {value!r} has no effect here; it applies only when {rule.when} "
                                f"(leave it at its default {_DEFAULTS[name]!r})", name)


def parse_param(key: str, value: Any, where: str = "") -> Any:
    """One parameter's value from loose input, as Params.from_dict reads it (fractions
    accepted); an unknown name is refused with the closest known one."""
    names = Params.field_names()
    prefix = f"{where}: " if where else ""
    if key not in names:
        close = difflib.get_close_matches(key, names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ParameterError(f"{prefix}unknown parameter {key!r}{hint}")
    return _coerce(key, value, prefix)


# Words read as "no value" for an optional parameter (f_th, extent, ...). Where "none" is
# one of a choice's values (preconditioner, threshold_disorder), it stays that value.
NONE_WORDS = ("none", "null")


def _coerce(key: str, value: Any, prefix: str) -> Any:
    if key == "snapshots":
        return _coerce_snapshots(value, prefix)
    if key == "extent" and isinstance(value, str) and value.strip().lower() == "auto":
        return None                      # as the README's table calls the automatic extent
    if isinstance(value, str) and value.strip().lower() in NONE_WORDS:
        if key in _OPTIONAL:
            return None
        value = "none"                   # a choice's own value, or refused below as not a number
    try:
        if value is None:
            return None
        kind = _KINDS[key]
        if key in CHOICES and isinstance(value, str) and value.strip().lower() in CHOICES[key]:
            return value.strip().lower()           # "SI", "Batch", " paraboloid"
        if key == "max_indent":
            if isinstance(value, str) and value.strip().lower() == "auto":
                return "auto"
            try:
                return parse_number(value, key)
            except ParameterError:
                raise ParameterError(f"max_indent: cannot read {value!r}: give 'auto' (a preload deep enough "
                                     "for the pull-off) or a depth such as 0.05 or 1/20") from None
        if key == "k_th_coefficient":
            from .units import K_TH_COEFFICIENTS
            names = tuple(K_TH_COEFFICIENTS) + ("limit",)
            if isinstance(value, str) and value.strip().lower() in names:
                return value.strip().lower()      # case-blind, as the other names ("JKR")
            if isinstance(value, str) and value not in K_TH_COEFFICIENTS:
                try:
                    return parse_number(value, key)
                except ParameterError:
                    return value            # an unknown name: the validation names the choices
            return value
        if key == "allow" and isinstance(value, (list, tuple)):
            return ",".join(str(v) for v in value)
        if kind == "float":
            return parse_number(value, key)
        if kind == "int":
            if isinstance(value, numbers.Integral) and not isinstance(value, bool):
                return int(value)
            if isinstance(value, str) and re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", value.strip()):
                # exact: through a float, 2**53 + 1 became 2**53 (also as "9.007199254740993e15")
                exact = decimal.Decimal(value.strip())
                if exact != exact.to_integral_value():
                    raise ParameterError(f"{key}: expected a whole number, got {value!r}")
                return int(exact)
            number = parse_number(value, key)
            if not number.is_integer():
                raise ParameterError(f"{key}: expected a whole number, got {value!r}")
            return int(number)
        return value
    except ParameterError as exc:
        raise ParameterError(f"{prefix}{exc}") from None


def _finite(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{name}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ParameterError(f"{name}: must be finite, got {value!r}")
    return float(value)


def _positive(name: str, value: Any, upper: float = math.inf) -> None:
    v = _finite(name, value)
    if not 0.0 < v <= upper:
        bound = "" if upper == math.inf else f" and <= {upper:g}"
        raise ParameterError(f"{name}: must be > 0{bound}, got {v!r}")


def _choice(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        close = ([str(value).lower()] if str(value).lower() in allowed
                 else difflib.get_close_matches(str(value), allowed, n=1))
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ParameterError(f"{name}: unknown value {value!r}; allowed: {', '.join(allowed)}{hint}")


#: largest opening angle of the tree without a warning: its error bound is 0.088 of sum |f|/r
#: there (1.03 at 1), and against the direct sum the pull-off moved by at most 4.6e-6 at
#: theta 0.7 and by 9.2e-4, its indent 18 steps (square, 1/48), at theta 1 (bench.tree_pull_off)
LOOSE_THETA = 0.7

#: smallest tol: double precision rounds a force to 1.1e-16 of itself, so no solution's
#: residual lies much below 10x that (the solves reach 1e-15 at 1/32 and 1/128)
MIN_TOL = 1e-15

#: largest self_term: beyond it every coupling 1/r is under 1e-6 of C_ii, a Winkler
#: foundation (kernel='local'); at 1e300 the solver's squares overflowed mid-run
MAX_SELF_TERM = 1e6

#: most loading steps of a run (max_indent / step, or force control's peak load / load_step)
MAX_STEPS = 1e6

#: largest max_iter, max_rounds, max_unload_steps: the compiled loop holds them (and
#: counts up to them) in int64, and a cap beyond int64 overflowed there (zero CG
#: iterations, or a Numba error mid-run); 2^31 - 1 is far beyond any run that ends
MAX_CAP = 2 ** 31 - 1
#: largest seed: the tables store seeds as int64 (a larger one computed, and then no table
#: could be written)
MAX_SEED = 2 ** 63 - 1


def _integer(name: str, value: Any, low: int, high: int | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{name}: expected an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        rng = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ParameterError(f"{name}: must be {rng}, got {value!r}")


def _validate(p: Params) -> None:
    from .guards import GUARDS

    if not isinstance(p.allow, str):
        raise ParameterError(f"allow: expected guard names separated by commas, got {p.allow!r}")
    for name in filter(None, p.allow.split(",")):
        _choice("allow", name, tuple(GUARDS))
    _positive("spacing", p.spacing)     # its upper bounds: the radius and the grid (below)
    a = _finite("alpha", p.alpha)
    if not -1.0 <= a <= 3.0:
        raise ParameterError(f"alpha: must be in [-1, 3], got {a!r}")
    if p.k_th is None and p.f_th is None and p.units != "si":   # SI: _validate_units
        raise ParameterError("k_th / f_th: give one threshold, k_th (F_th = k_th A^alpha) or f_th")
    if p.k_th is not None and p.f_th is not None:
        raise ParameterError("k_th / f_th: give only one of k_th and f_th, not both (f_th has a default: "
                             "Params(k_th=..., f_th=None); Params.from_dict, replace and simulate clear it)")
    for name in ("k_th", "f_th"):
        value = getattr(p, name)
        if value is not None and _finite(name, value) < 0:
            raise ParameterError(f"{name}: must be >= 0 (a tensile threshold), got {value!r}")
    _positive("radius", p.radius)
    _choice("shape", p.shape, SHAPES)
    _choice("kernel", p.kernel, KERNELS)
    _positive("self_term", p.self_term, upper=MAX_SELF_TERM)
    _integer("neighbor_rings", p.neighbor_rings, 1, 64)
    _positive("c_w", p.c_w)
    _choice("operator", p.operator, OPERATORS)
    _positive("theta", p.theta, upper=1.0)
    _choice("layout", p.layout, LAYOUTS)
    j = _finite("jitter", p.jitter)
    if not 0.0 <= j < 0.5:
        raise ParameterError(f"jitter: must be in [0, 0.5) spacings so springs never cross, got {j!r}")
    _integer("seed", p.seed, 0, MAX_SEED)
    if p.max_indent != "auto":
        _positive("max_indent", p.max_indent)
    _positive("step", p.step)
    _choice("snap_rule", p.snap_rule, SNAP_RULES)
    if not MIN_TOL <= _finite("tol", p.tol) <= 1e-2:
        why = (f" (below {MIN_TOL:g} the residual is under the rounding of the forces themselves: CG's "
               "recursive residual falls on and reports what no solution has, and at 1e-200 it underflowed "
               "to a division by zero)" if p.tol < MIN_TOL else "")
        raise ParameterError(f"tol: must be in [{MIN_TOL:g}, 1e-2], got {p.tol!r}{why}")
    _integer("max_iter", p.max_iter, 1, MAX_CAP)
    _integer("max_rounds", p.max_rounds, 1, MAX_CAP)
    if p.max_unload_steps is not None:
        _integer("max_unload_steps", p.max_unload_steps, 1, MAX_CAP)
    _choice("preconditioner", p.preconditioner, PRECONDITIONERS)
    _positive("extent_margin", p.extent_margin)
    if p.extent is not None:
        _positive("extent", p.extent)
    _validate_units(p)
    _validate_surface(p)
    # relations between parameters
    dmax = p.delta_max
    # under force control with a max_load the depth is that load's (Hertz or punch)
    depth = _depth_text(p, dmax)
    if p.step > dmax:
        fix = "; lower step or raise max_load" if p.control == "force" and p.max_load is not None else ""
        raise ParameterError(f"step: must be <= {depth}, got {p.step!r}{fix}")
    if dmax / p.step > MAX_STEPS:
        raise ParameterError(f"step: {depth} / step = {dmax / p.step:.3g} steps; must be <= {MAX_STEPS:g}")
    if p.shape == "sphere" and dmax >= p.radius:
        if p.control == "force" and p.max_load is not None:
            from .units import unit_suffixes
            raise ParameterError(f"max_load: {p.max_load:g}{unit_suffixes(p)[1]} would press a sphere of radius {p.radius:g} in by "
                                 f"{dmax:.3g} (its Hertz depth), deeper than its radius; lower max_load")
        raise ParameterError(f"max_indent: must be < radius ({p.radius:g}) for a sphere, got {dmax!r}")
    _check_map_covers(p)
    hw = p.half_width
    if p.spacing > hw and p.extent is not None:       # the extent given is the likelier slip
        raise ParameterError(f"extent: the grid half-width {hw:g} is smaller than the spacing {p.spacing:g}, "
                             "so the grid would be its centre spring alone; enlarge extent or shrink spacing")
    if p.spacing > hw:
        raise ParameterError(f"spacing: must be <= the grid half-width ({hw:g}); got {p.spacing!r}")
    cells = hw / p.spacing              # a float: inf for an absurd extent (math.ceil would raise)
    if cells > 4096:                    # 2 ceil(cells) + 1 > 8193 springs a side
        sides = 2.0 * cells + 1.0
        n_side = (f"{2 * math.ceil(cells) + 1}" if cells < 1e9 else f"{sides:.3g}"
                  if math.isfinite(sides) else "more than 1e+308")
        if p.shape == "height_map":     # the map sets the region: its size as read is the suspect
            raise ParameterError(f"height_map/spacing: the map, read as {2 * hw:g} wide, would need {n_side} "
                                 f"springs a side at spacing {p.spacing:g}; the limit is 8193 (enlarge spacing, "
                                 "or check the map's pixel size and length unit)")
        raise ParameterError(f"extent/spacing: the grid would have {n_side} springs a side; "
                             f"the limit is 8193 (shrink extent or enlarge spacing)")
    if p.kernel == "neighbors" and p.layout != "square":
        raise ParameterError("kernel: 'neighbors' counts rings of the square grid; use layout='square'")
    if p.operator_used == "fft" and p.layout != "square":
        raise ParameterError(f"operator: 'fft' needs a regular square grid, but layout={p.layout!r}; "
                             "use operator='tree' or 'direct'")
    if p.preconditioner in ("stencil", "fft") and p.layout != "square":
        raise ParameterError(f"preconditioner: {p.preconditioner!r} needs layout='square'; use 'auto', 'diagonal' or 'none'")
    _validate_surface_relations(p)
    _check_applies(p)


def _coerce_snapshots(value: Any, prefix: str) -> Any:
    """``snapshots``: "none" (also None), "events", or a whole number k, given as a number or as text."""
    if value is None:
        return "none"
    if isinstance(value, str) and value.strip().lower() in SNAPSHOT_MODES:
        return value.strip().lower()
    if isinstance(value, str):
        try:
            number = parse_number(value, "snapshots")
        except ParameterError:
            raise ParameterError(f"{prefix}snapshots: expected 'none', 'events' or a whole number k "
                                 f"(every k-th step), got {value!r}") from None
        return int(number) if number.is_integer() else number
    if isinstance(value, float) and value.is_integer():
        return int(value)               # as every whole-number parameter (a TOML 5.0)
    return value


def _validate_protocol(p: Params) -> None:
    """The loading protocol and the field output (tfm.protocol, tfm.snapshots)."""
    _choice("control", p.control, CONTROLS)
    snaps = p.snapshots
    if isinstance(snaps, str):
        if snaps not in SNAPSHOT_MODES:     # "allowed: none, events" left out the step count
            raise ParameterError(f"snapshots: expected 'none', 'events' or a whole number k >= 1 (every k-th "
                                 f"step), got {snaps!r}")
    else:
        _integer("snapshots", snaps, 1)
    if p.control == "displacement":
        return                          # max_load and load_step: see APPLIES
    if p.shape == "height_map":
        # its peak load would be a Hertz load of a radius that does not apply, and an
        # explicit max_load has no closed-form depth to size the run. First: the other
        # messages ("leave max_indent 'auto'") led only to this one
        raise ParameterError("control: 'force' is not available for shape='height_map'; use "
                             "control='displacement' with max_indent")
    if p.max_load is not None:
        _positive("max_load", p.max_load)
        if p.max_indent != "auto":
            raise ParameterError("max_indent: under control='force' with an explicit max_load the preload "
                                 "is a load; leave max_indent 'auto' (it then follows max_load)")
    elif p.shape == "flat_punch":
        raise ParameterError("max_load: control='force' on a flat punch needs an explicit max_load "
                             "(there is no Hertz load to derive it from)")
    if p.load_step is not None:
        _positive("load_step", p.load_step)


def _validate_protocol_relations(p: Params) -> None:
    if p.control == "force" and p.peak_load / p.load_decrement > MAX_STEPS:
        raise ParameterError(f"load_step: the peak load / load_step = {p.peak_load / p.load_decrement:.3g} load "
                             f"steps; must be <= {MAX_STEPS:g}")
    if p.control == "force" and p.load_step is not None:
        if p.load_step > p.peak_load:
            unit = " N" if p.units == "si" else ""
            peak = (f"max_load ({p.peak_load:g}{unit})" if p.max_load is not None else
                    f"the peak load ({p.peak_load:g}{unit}, the Hertz load at max_indent; max_load is unset)")
            raise ParameterError(f"load_step: must be <= {peak}, got {p.load_step!r}")


# ---- roughness, height maps, threshold disorder (tfm.surfaces, tfm.threshold) ----
# (which of these parameters apply when: APPLIES above)
#: largest coefficient of variation of the uniform disorder: keeps every F_th >= 0
MAX_UNIFORM_WIDTH = 1.0 / math.sqrt(3.0)
#: coefficient of variation of the Weibull disorder: Weibull modulus from 85 down to 0.54
WEIBULL_WIDTH_RANGE = (0.015, 2.0)


def _validate_surface(p: Params) -> None:
    """Roughness, height map and threshold disorder: values on their own."""
    h = _finite("hurst", p.hurst)
    if not 0.0 < h < 1.0:
        raise ParameterError(f"hurst: must be in (0, 1) (self-affine Hurst exponent), got {h!r}")
    for name in ("rms_slope", "rms_height"):
        if _finite(name, getattr(p, name)) < 0:
            raise ParameterError(f"{name}: must be >= 0 (0 = smooth), got {getattr(p, name)!r}")
    if p.rms_slope > 0 and p.rms_height > 0:
        raise ParameterError("rms_slope / rms_height: give one of them (the other sets itself), not both")
    rough = _rough(p)
    for name in ("short_cutoff", "long_cutoff"):
        if getattr(p, name) is not None:
            _positive(name, getattr(p, name))
    # the ranges matter only on a rough surface: on a smooth one a cutoff has no effect and is
    # refused as such (_check_applies); its range error first named a parameter never given
    if rough and p.short_cutoff is not None and p.short_cutoff < 2.0 * p.spacing * (1 - 1e-12):
        raise ParameterError(f"short_cutoff: must be >= 2 spacings ({2 * p.spacing:g}, the shortest "
                             f"wavelength the grid carries), got {p.short_cutoff!r}")
    if rough and p.long_cutoff is not None:
        short = p.short_cutoff if p.short_cutoff is not None else 4.0 * p.spacing
        if short >= p.long_cutoff:
            raise ParameterError(f"short_cutoff: must be < long_cutoff ({p.long_cutoff:g}), got {short!r}"
                                 + ("" if p.short_cutoff is not None else " (the default, 4 spacings)"))
    if _finite("rolloff", p.rolloff) < 0:
        raise ParameterError(f"rolloff: must be >= 0 (PSD at wavelengths longer than long_cutoff = rolloff^2 C(q_L)), got {p.rolloff!r}")
    _integer("roughness_seed", p.roughness_seed, 0, MAX_SEED)
    # under force control with a max_load, 'auto' is that load's depth (it sizes the grid)
    by_load = p.control == "force" and p.max_load is not None
    if rough and p.max_indent == "auto" and not by_load:
        raise ParameterError("max_indent: 'auto' assumes a smooth body; give a number for a rough surface "
                             "(e.g. the smooth auto value plus 3 rms heights)"
                             + (", or under force control a max_load" if p.control == "force" else ""))
    if (p.max_indent == "auto" and not by_load and p.shape in ("sphere", "paraboloid")
            and p.threshold_force == 0.0):
        raise ParameterError("max_indent: 'auto' sizes the preload by the adhesion (the JKR contact radius); "
                             "with no adhesion (every F_th = 0) give a number")
    # height map
    is_map = p.shape == "height_map"
    if is_map and p.height_map is None:
        raise ParameterError("height_map: shape='height_map' needs height_map = <path to a .npy map>")
    if not is_map and p.height_map is not None:
        raise ParameterError(f"height_map: applies only to shape='height_map'; got shape={p.shape!r}")
    if is_map:
        if not isinstance(p.height_map, (str, os.PathLike)) or not str(p.height_map).strip():
            # an array's repr came back as "no such file '[[ 1.257e-04 ...'"
            got = f"a {type(p.height_map).__name__}" if not isinstance(p.height_map, str) else "''"
            raise ParameterError(f"height_map: expected the path of a map file (.npy, or a format "
                                 f"SurfaceTopography reads), got {got}; save an array with numpy.save")
        if p.map_pixel_size is not None:
            _positive("map_pixel_size", p.map_pixel_size)
        if p.max_indent == "auto":
            raise ParameterError("max_indent: 'auto' needs a sphere's JKR radius; give a number for a height map")
        from .surfaces import MapError, load_height_map, unit_to_metres
        try:
            hm = load_height_map(p.height_map)
            to_m = unit_to_metres(hm.unit, p)
        except MapError as exc:
            raise ParameterError(str(exc)) from None
        if p.map_pixel_size is not None and hm.pixel_size is not None:
            # the file's heights are taken in metres (its unit); a pixel given in other
            # terms would scale one and not the other. The file's own value given again is
            # fine (files store their sizes in single precision: 1e-6)
            own = hm.pixel_size * to_m
            if not math.isclose(p.map_pixel_size, own, rel_tol=1e-6):
                raise ParameterError(
                    f"map_pixel_size: {p.height_map} gives its own pixel size, {hm.pixel_size:g}{' ' + hm.unit if hm.unit else ''} "
                    f"= {own:g} m, and its heights in {hm.unit or 'm'}, both taken in metres"
                    f"{' (L* = 1 m in paper units)' if p.units == 'paper' else ''}; map_pixel_size applies "
                    f"to maps without one (.npy, text), got {p.map_pixel_size!r}. To rescale the map, save its "
                    "heights as .npy and give map_pixel_size")
            # the file's own value given again: the record (and the run id) is the one
            # made without it, since the physics is the same
            object.__setattr__(p, "map_pixel_size", None)
        if p.height_map_hash is None:
            object.__setattr__(p, "height_map_hash", hm.sha256)
        elif p.height_map_hash != hm.sha256:
            raise ParameterError(f"height_map: the content of {p.height_map!r} changed since this record "
                                 f"was made (sha256 {hm.sha256[:12]}..., record {p.height_map_hash[:12]}...)")
    # threshold disorder
    _choice("threshold_disorder", p.threshold_disorder, DISORDERS)
    w = _finite("disorder_width", p.disorder_width)
    if p.threshold_disorder != "none" and w == 0.0:
        # "must be in [0.015, 2] ... got 0.0" read as if a zero had been given
        raise ParameterError(f"disorder_width: must be > 0 with threshold_disorder={p.threshold_disorder!r} (the "
                             "std/mean of the thresholds, e.g. 0.3); it is 0 (also its default when not given)")
    if p.threshold_disorder == "uniform" and not 0.0 < w <= MAX_UNIFORM_WIDTH:
        raise ParameterError(f"disorder_width: must be in (0, {MAX_UNIFORM_WIDTH:.4f}] for 'uniform' "
                             f"(std/mean; 1/sqrt(3) keeps F_th >= 0), got {w!r}")
    lo, hi = WEIBULL_WIDTH_RANGE
    if p.threshold_disorder == "weibull" and not lo <= w <= hi:
        raise ParameterError(f"disorder_width: must be in [{lo:g}, {hi:g}] for 'weibull' (std/mean), got {w!r}")
    _integer("disorder_seed", p.disorder_seed, 0, MAX_SEED)


def _validate_surface_relations(p: Params) -> None:
    """Roughness and map checks against the grid (after the extent is known)."""
    hw = p.half_width
    side = (2 * math.ceil(hw / p.spacing - 1e-9) + 1) * p.spacing
    if _rough(p) and p.short_cutoff is not None and p.short_cutoff > side * (1 + 1e-12):
        raise ParameterError(f"short_cutoff: must be <= the grid side ({side:g}): no wavelength of the grid is "
                             f"longer than its side, so none would be left, got {p.short_cutoff!r}")
    if _rough(p) and p.long_cutoff is not None:
        if p.long_cutoff > side * (1 + 1e-12):
            raise ParameterError(f"long_cutoff: must be <= the grid side ({side:g}); no wavevector of the "
                                 f"grid lies below a longer cutoff, got {p.long_cutoff!r}")
    if _rough(p):
        from .surfaces import default_short_cutoff, grid_side, has_modes
        short = p.short_cutoff if p.short_cutoff is not None else default_short_cutoff(p.spacing)
        if not has_modes(grid_side(p), p.spacing, short, None):
            # only the default can get here (a given short_cutoff > side is refused above)
            raise ParameterError(f"short_cutoff: the grid (side {side:g}) is narrower than the default short "
                                 f"cutoff, 4 spacings = {short:g}, so the surface would have no roughness; "
                                 "give a smaller short_cutoff or a larger grid (extent)")
        if not has_modes(grid_side(p), p.spacing, short, p.long_cutoff, p.rolloff):
            raise ParameterError(f"short_cutoff / long_cutoff: no wavevector of the grid (side {side:g}) lies "
                                 f"between the cutoffs {short:g} and {p.long_cutoff:g} with rolloff = 0, so the "
                                 "surface would have no roughness; widen the band or give rolloff > 0")
        if (p.long_cutoff is not None and p.rolloff != _DEFAULTS["rolloff"]
                and p.long_cutoff >= side * (1 - 1e-12)):
            # the grid's longest wavelength is its side: no mode lies below q_L
            raise ParameterError(f"rolloff: {p.rolloff!r} has no effect here: long_cutoff {p.long_cutoff:g} is the "
                                 f"grid side, so no wavevector of the grid lies below q_L = 2 pi / long_cutoff; "
                                 "give a shorter long_cutoff or leave rolloff at 1")


def _depth_text(p: Params, dmax: float) -> str:
    """The preload depth as messages name it: max_indent, or, under force control, the
    depth of max_load as the user gave it (newtons and metres for an SI record)."""
    from .units import unit_suffixes

    length, force = unit_suffixes(p)
    if p.control == "force" and p.max_load is not None:
        return f"the depth of max_load {p.max_load:g}{force} ({dmax:.3g}{length})"
    if p.max_indent == "auto":
        from .theory import AUTO_PRELOAD_CAP
        cap = f", capped at {AUTO_PRELOAD_CAP:g} R" if dmax >= AUTO_PRELOAD_CAP * p.radius * (1 - 1e-12) else ""
        return f"the automatic preload depth ({dmax:.3g}{length}{cap}; max_indent='auto')"
    return f"max_indent ({dmax:g}{length})"


def _check_map_covers(p: Params) -> None:
    """A height map covers the grid (before the spacing is checked against the grid: a
    map too small for one spring a side is the map's fault, not the spacing's)."""
    if p.shape == "height_map":
        from .geometry import layout_reach
        from .surfaces import load_height_map, map_pixel, map_reach
        hw = p.half_width
        hm = load_height_map(p.height_map)
        avail = min(map_reach(p, hm))
        need = layout_reach(p, hw)
        nx, ny = hm.heights.shape
        if avail <= 0:
            # a grid centred on a pixel needs one on each side of it: with 2 along a side the
            # map reaches +-0, and no extent or spacing could help (the message said they might)
            short = " and ".join(axis for axis, n in (("x", nx), ("y", ny)) if n < 3) or "x or y"
            raise ParameterError(f"height_map: the map ({nx} x {ny} pixels) has fewer than 3 pixels along {short}: "
                                 "the grid is centred on a pixel and needs one on each side of it, so no grid "
                                 "beyond one spring fits; a map needs at least 3 x 3 pixels (use a larger map)")
        if hw <= 0 or need > avail * (1 + 1e-9):
            own = (f", the file's {hm.pixel_size:g} {hm.unit or ''} converted to metres"
                   + (" (L* = 1 m in paper units)" if p.units == "paper" else "")
                   if hm.pixel_size is not None and p.map_pixel_size is None else "")
            raise ParameterError(f"height_map: the map ({nx} x {ny} pixels of {map_pixel(p, hm):g}{own}) covers "
                                 f"+-{avail:g}, smaller than the grid (half-width {max(need, p.spacing):g}"
                                 + (f": extent {hw:g} plus the jitter's reach, {p.jitter:g} spacings"
                                    if p.layout == "jittered" and hw > 0 else "")
                                 + "); use a larger map, a smaller extent or a finer spacing")


def _validate_units(p: Params) -> None:
    """units, the material and K_th's coefficient (tfm.units)."""
    _choice("units", p.units, UNITS)
    coefficient = p.k_th_coefficient
    if coefficient == "limit" and p.units == "si" and p.work_of_adhesion is not None:
        # a measured value that a longer campaign may refine: the record keeps the number,
        # so its run id and its K_th stay reproducible from the table
        from .units import limit_coefficient
        if p.kernel != "boussinesq":
            raise ParameterError(f"k_th_coefficient: 'limit' was measured with the boussinesq kernel, "
                                 f"not {p.kernel!r}; give the coefficient as a number")
        if p.layout != "square":
            raise ParameterError(f"k_th_coefficient: 'limit' was measured on the square layout, not "
                                 f"{p.layout!r}; give the coefficient as a number")
        try:
            coefficient = limit_coefficient(p.self_term)
        except ValueError as e:
            raise ParameterError(str(e)) from None
        object.__setattr__(p, "k_th_coefficient", coefficient)
    if isinstance(coefficient, str):
        from .units import K_TH_COEFFICIENTS
        _choice("k_th_coefficient", coefficient, tuple(K_TH_COEFFICIENTS) + ("limit",))
    elif _finite("k_th_coefficient", coefficient) <= 0:
        raise ParameterError(f"k_th_coefficient: must be > 0 or a name (paper, jkr, limit), "
                             f"got {coefficient!r}")
    if p.units == "paper":
        return                              # SI-only fields: APPLIES
    if p.youngs_modulus is None or p.poisson_ratio is None:
        raise ParameterError("youngs_modulus / poisson_ratio: units='si' needs both (Pa, and nu in (-1, 0.5])")
    _positive("youngs_modulus", p.youngs_modulus)
    nu = _finite("poisson_ratio", p.poisson_ratio)
    if not -1.0 < nu <= 0.5:
        raise ParameterError(f"poisson_ratio: must be in (-1, 0.5], got {nu!r}")
    if p.k_th is not None:
        raise ParameterError("k_th: with units='si' give work_of_adhesion (J/m^2), from which K_th follows, "
                             "or an explicit f_th in newtons; k_th is in paper units")
    if (p.work_of_adhesion is None) == (p.f_th is None):
        which = "neither was given" if p.f_th is None else "not both"
        raise ParameterError("work_of_adhesion / f_th: units='si' needs one threshold: work_of_adhesion "
                             f"(J/m^2) or f_th (N); {which}")
    if p.work_of_adhesion is not None:
        if _finite("work_of_adhesion", p.work_of_adhesion) < 0:
            raise ParameterError(f"work_of_adhesion: must be >= 0 (J/m^2), got {p.work_of_adhesion!r}")
        if p.alpha != 0.75:
            raise ParameterError(f"alpha: must be 0.75 with work_of_adhesion (K_th = pi sqrt(3 G gamma/"
                                 f"(c (1 - nu))) holds for F_th = K_th A^0.75), got {p.alpha!r}")
    if p.kernel != "boussinesq":
        raise ParameterError(f"kernel: units='si' needs the elastic half-space kernel 'boussinesq' "
                             f"(the others are not elastic bodies with a modulus), got {p.kernel!r}")
    mixed = " with units='si' every length is in metres (paper-unit values mixed in?)"
    if p.shape != "height_map" and p.spacing >= p.radius:
        raise ParameterError(f"spacing: must be < radius ({p.radius:g} m), got {p.spacing!r};{mixed}")
    dmax = p.delta_max           # its own errors name their parameter (not always a length)
    if p.step > dmax:
        raise ParameterError(f"step: must be <= {_depth_text(p, dmax)}, got {p.step!r};{mixed}")
