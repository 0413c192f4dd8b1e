"""Campaign files (TOML) -> an ordered list of validated runs.

A campaign file names a study, fixes base parameters and sweeps the others::

    name = "smoke"                  # results go to results/smoke/
    description = "what this study is for"
    [base]                          # fixed for every run (any Params field)
    spacing = "1/16"
    [sweep]                         # cartesian product of these lists
    alpha = [0.5, 0.75]
    [[zip]]                         # lists of one [[zip]] table move together
    radius = [0.5, 1.0]
    max_indent = [0.025, 0.05]

The runs are the product of the ``[sweep]`` axes (in file order), then the ``[[zip]]``
groups (in file order); the last axis varies fastest. The ``[sweep]`` axes come first
wherever the tables stand (TOML parsers do not keep the order of [[zip]] tables around
[sweep], and existing campaigns keep their run order). Every run is validated through
``Params.from_dict`` before anything runs, so a typo or a bad value fails at once with
the file, the parameter and the reason; so is every meaningful-run guard of
``tfm.guards`` (not the memory one: the file may run on another machine). A file that
expands to more than ``DEFAULT_MAX_RUNS`` runs is refused, counted before anything is
built, unless it says ``max_runs = N`` (or the CLI gets ``--max-runs N``). Optional parameters (``k_th``, ``f_th``,
``extent``, ``max_unload_steps``) take the string ``"none"`` for None, since TOML has
no null.
"""
from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import re
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..guards import GuardError, check, kernel_check_key
from ..params import APPLIES, InapplicableError, ParameterError, Params, ParameterWarning, parse_param

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - python 3.10
    import tomli as tomllib

TOP_LEVEL_KEYS = ("name", "description", "max_runs", "base", "sweep", "zip")
# the top-level keys that are tables of parameters
TABLE_KEYS = ("base", "sweep", "zip")


def _no_top_level_keys(table, section: str, where: str) -> None:
    """Refuse a top-level key found inside a table: TOML puts every key written after a
    [table] header into that table ("[base]: unknown parameter 'sweep' (did you mean
    'step'?)" and "[sweep] max_runs: ... needs a list" misled)."""
    if not isinstance(table, Mapping):
        return
    for key in table:
        if key in TOP_LEVEL_KEYS:
            own = f", or as a table of its own, {'[[zip]]' if key == 'zip' else f'[{key}]'}" \
                if key in TABLE_KEYS else ""
            raise CampaignError(f"{where}: {section}: {key!r} is a top-level key, not a parameter: TOML "
                                f"puts every key written after a [table] header into that table; write "
                                f"it before the first [table] of the file{own}")


# Expanding and validating costs ~0.2 ms of CPU a run (10,000 runs: 2.0 s), so the
# default answers within seconds; a larger campaign must say it means it (max_runs = N).
DEFAULT_MAX_RUNS = 10_000
EXPAND_SECONDS = 2e-4
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


class CampaignError(ParameterError):
    """A campaign file is missing, malformed, or expands to an invalid run."""


@dataclass(frozen=True)
class Run:
    """One expanded run: its position in the campaign, its swept values and its record."""

    index: int
    params: Params
    swept: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()        # said before the run starts (tfm.guards.check)

    @property
    def run_id(self) -> str:
        return self.params.run_id


@dataclass(frozen=True)
class CampaignSpec:
    """A parsed, fully validated campaign: every run already built as a ``Params``."""

    name: str
    description: str
    base: dict[str, Any]
    sweep: dict[str, list]
    zips: tuple[dict[str, list], ...]
    runs: tuple[Run, ...]
    source: str = "<dict>"
    digest: str = ""            # sha256 of the parsed content (JSON, sorted keys)
    origin: str = ""            # the file's resolved path ("" for a dict)

    @property
    def run_ids(self) -> list[str]:
        return [r.run_id for r in self.runs]

    @property
    def swept_names(self) -> list[str]:
        return list(self.sweep) + [k for group in self.zips for k in group]


def load_spec(path: str | Path, max_runs: int | None = None) -> CampaignSpec:
    """Read and validate a campaign file; raises CampaignError naming the file."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise CampaignError(f"{path}: no such campaign file") from None
    except OSError as exc:
        raise CampaignError(f"{path}: cannot read the campaign file: {exc.strerror}") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        # an editor's byte order mark: TOML forbids it, and the parser's message only
        # pointed at line 1, column 1
        raise CampaignError(f"{path}: not valid TOML: the file starts with a UTF-8 byte order mark (BOM), which "
                            "TOML does not allow; save it as UTF-8 without BOM")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{path}: not valid TOML: {exc}") from None
    return spec_from_dict(data, source=str(path), max_runs=max_runs, _origin=str(path.resolve()))


def count_runs(sweep: Mapping[str, list], zips: list[Mapping[str, list]]) -> int:
    """How many runs the axes expand to, without expanding them."""
    return math.prod(len(v) for v in sweep.values()) * math.prod(len(next(iter(g.values()))) for g in zips)


def spec_from_dict(data: Mapping[str, Any], *, source: str = "<dict>", max_runs: int | None = None,
                   _origin: str = "") -> CampaignSpec:
    """Validate a campaign given as a mapping (the parsed TOML) and expand its runs.
    ``max_runs`` confirms a campaign larger than ``DEFAULT_MAX_RUNS`` (as the key does)."""
    where = source
    if not isinstance(data, Mapping):
        raise CampaignError(f"{where}: expected a table of top-level keys, got {type(data).__name__}")
    for key in data:
        if key not in TOP_LEVEL_KEYS:
            raise CampaignError(f"{where}: unknown top-level key {key!r}{_hint(key, TOP_LEVEL_KEYS)}; "
                                f"allowed: {', '.join(TOP_LEVEL_KEYS)}")
    name = data.get("name")
    if name is None:
        # TOML puts a key written after [base] into that table: say so, not "got None"
        inside = [section for section, table in data.items() if isinstance(table, Mapping) and "name" in table]
        if inside:
            raise CampaignError(f"{where}: name: found inside [{inside[0]}]; the top-level keys (name, "
                                "description, ...) must come before the first [table] of the file")
        raise CampaignError(f"{where}: missing key 'name' (the campaign's name, its results folder: "
                            "results/<name>/), e.g. name = \"sweep1\" before the first [table]")
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise CampaignError(f"{where}: name: expected a folder-safe name (letters, digits, '.', '_', '-'; "
                            f"starting with a letter or digit), got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise CampaignError(f"{where}: description: expected a string, got {description!r}")

    _no_top_level_keys(data.get("base"), "[base]", where)
    _no_top_level_keys(data.get("sweep"), "[sweep]", where)
    base = _table(data.get("base", {}), "[base]", where)
    for key, value in base.items():
        if isinstance(value, list):       # read as one value: "cannot read [0.5, 0.75] as a number"
            raise CampaignError(f"{where}: [base] {key} = {value!r}: [base] holds one value per parameter; "
                                "a list of values goes in [sweep] (every combination) or [[zip]] (side by side)")
    sweep = {k: _axis(v, f"[sweep] {k}", where) for k, v in _table(data.get("sweep", {}), "[sweep]", where).items()}
    raw_zips = data.get("zip", [])
    if isinstance(raw_zips, Mapping):          # a single [zip] table
        raw_zips = [raw_zips]
    if not isinstance(raw_zips, list):
        raise CampaignError(f"{where}: zip: expected [[zip]] tables, got {raw_zips!r}")
    zips = []
    for g, group in enumerate(raw_zips):
        label = f"[[zip]] #{g + 1}"
        _no_top_level_keys(group, label, where)
        group = {k: _axis(v, f"{label} {k}", where) for k, v in _table(group, label, where).items()}
        if not group:
            raise CampaignError(f"{where}: {label}: empty; list at least one parameter")
        lengths = {k: len(v) for k, v in group.items()}
        if len(set(lengths.values())) > 1:
            detail = ", ".join(f"{k} has {n}" for k, n in lengths.items())
            raise CampaignError(f"{where}: {label}: zipped lists must have the same length ({detail})")
        zips.append(group)

    limit = max_runs if max_runs is not None else data.get("max_runs", DEFAULT_MAX_RUNS)
    if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
        raise CampaignError(f"{where}: max_runs: expected a whole number >= 1, got {limit!r}")
    count = count_runs(sweep, zips)
    if count > limit:
        raise CampaignError(f"{where}: expands to {count:,} runs, more than max_runs = {limit:,}. "
                            f"If you mean it, set max_runs = {count} at the top of the file "
                            f"(or pass --max-runs {count})")

    # each parameter is set in one place only
    seen: dict[str, str] = {}
    sections = [("[base]", base)] + [("[sweep]", sweep)] + [(f"[[zip]] #{g + 1}", z) for g, z in enumerate(zips)]
    names = Params.field_names()
    for section, table in sections:
        for key in table:
            if key not in names:
                hint = _hint(key, names)
                top = difflib.get_close_matches(key, TOP_LEVEL_KEYS, n=1)
                if top and not hint:
                    hint = (f" (a top-level key such as {top[0]!r} must come before the first "
                            "[table] of the file)")
                raise CampaignError(f"{where}: {section}: unknown parameter {key!r}{hint}")
            if key in seen:
                raise CampaignError(f"{where}: parameter {key!r} is set in both {seen[key]} and {section}; "
                                    "set it in one place")
            seen[key] = section

    if count > DEFAULT_MAX_RUNS:
        # confirmed, but a million runs take minutes to check: not in silence
        print(f"tfm: note: {where}: checking the parameters of {count:,} runs (about "
              f"{count * EXPAND_SECONDS:,.0f} s on a laptop)", file=sys.stderr, flush=True)
    runs = tuple(_expand(base, sweep, zips, where))
    by_id: dict[str, Run] = {}
    for run in runs:
        if run.run_id in by_id:
            first = by_id[run.run_id]
            raise CampaignError(f"{where}: run {run.index} {_label(run.swept)} is the same run as run "
                                f"{first.index} {_label(first.swept)} (equal parameters); "
                                "remove the duplicate value")
        by_id[run.run_id] = run
    # the content hash is of the parsed file, so comments and layout do not count
    digest = hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()
    return CampaignSpec(name=name, description=description, base=dict(base), sweep=sweep,
                        zips=tuple(zips), runs=runs, source=source, digest=digest, origin=_origin)


def _expand(base, sweep, zips, where):
    kernels_checked: dict[tuple, str | None] = {}     # kernel_check_key -> refusal, if any
    axes = [[{k: v} for v in values] for k, values in sweep.items()]
    axes += [[dict(zip(group, values)) for values in zip(*group.values())] for group in zips]
    # a [base] key said the same for every run, once per run; said once, naming the runs
    said: dict[str, list[tuple[int, str]]] = {}
    # a [base] key with no effect in some runs (hurst where rms_height is swept through 0):
    # left at its default there, and said; refused if it has an effect in none
    unused: dict[str, tuple[str, list[int]]] = {}
    for index, combo in enumerate(itertools.product(*axes)):
        swept: dict[str, Any] = {}
        for part in combo:
            swept.update(part)
        values = {**base, **swept}           # "none" is read by Params.from_dict (params.NONE_WORDS)
        label = f"{where}: run {index} {_label(swept)}".rstrip()
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ParameterWarning)
                # a swept or zipped list gives every run a value: the default value there
                # says "not used in this run", so only [base] keys warn
                for key in swept:
                    warnings.filterwarnings("ignore", message=f".*: {re.escape(key)}: given but",
                                            category=ParameterWarning)
                while True:
                    try:
                        params = Params.from_dict(values, where=label)
                        break
                    except InapplicableError as exc:
                        if exc.name not in base or exc.name in swept:
                            raise
                        unused.setdefault(exc.name, (str(exc).removeprefix(f"{label}: "), []))[1].append(index)
                        values.pop(exc.name)
            for w in caught:
                if issubclass(w.category, ParameterWarning):
                    said.setdefault(str(w.message).removeprefix(f"{label}: "), []).append((index, label))
                else:
                    warnings.warn(w.message, w.category, stacklevel=2)
            notes = tuple(check(params, memory=False))
            _check_kernel(params, kernels_checked, label)
        except GuardError as exc:
            raise CampaignError(f"{label}: {exc}") from None
        except ParameterError as exc:
            # status, too, needs the map: its content hash is part of each run id
            hint = ("; a campaign needs its height maps to know its runs (a map's content hash is part of "
                    "each run id): restore the file, or point height_map at where it is now"
                    if "height_map: no such file" in str(exc) else "")
            raise CampaignError(f"{exc}{hint}") from None
        yield Run(index=index, params=params, swept=swept, notes=notes)
    for name, (text, runs) in unused.items():
        if len(runs) == index + 1:
            raise CampaignError(f"{where}: [base] {text}; in every run")
        which = ", ".join(str(i) for i in runs[:8]) + (", ..." if len(runs) > 8 else "")
        default = Params.__dataclass_fields__[name].default
        warnings.warn(f"{where}: run{'s' if len(runs) > 1 else ''} {which} ({len(runs)} of {index + 1}): [base] {name} = {base[name]!r} has no "
                      f"effect there (it applies only when {APPLIES[name].when}), so they run with its default "
                      f"{default!r}; the other runs use it", ParameterWarning, stacklevel=3)
    for text, runs in said.items():
        if len(runs) == 1:
            warnings.warn(f"{runs[0][1]}: {text}", ParameterWarning, stacklevel=3)
        else:
            which = ", ".join(str(i) for i, _ in runs[:8]) + (", ..." if len(runs) > 8 else "")
            warnings.warn(f"{where}: runs {which} ({len(runs)} of {index + 1}): {text}", ParameterWarning,
                          stacklevel=3)


def _check_kernel(params: Params, checked: dict, label: str) -> None:
    """The compliance must be positive definite (tfm run refuses it before the run; a
    campaign ran such files and failed each run at its start). One check per distinct
    kernel and grid; the default kernel on the square grid needs none (and no engine
    import, so that expanding a campaign stays fast)."""
    key = kernel_check_key(params)
    if key is None:
        return
    if key not in checked:
        from ..operators import check_record

        try:
            check_record(params)
            checked[key] = None
        except ParameterError as exc:
            checked[key] = str(exc)
    if checked[key]:
        raise ParameterError(f"{label}: {checked[key]}")     # which file and run, as every refusal


def _table(value: Any, label: str, where: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise CampaignError(f"{where}: {label}: expected a table of parameter = value, got {value!r}")
    return dict(value)


def _axis(value: Any, label: str, where: str) -> list:
    if not isinstance(value, list):
        raise CampaignError(f"{where}: {label}: a swept parameter needs a list of values, got {value!r} "
                            "(fix it in [base] instead)")
    if not value:
        raise CampaignError(f"{where}: {label}: empty list; give at least one value")
    for v in value:
        if isinstance(v, (list, dict)):
            raise CampaignError(f"{where}: {label}: values must be numbers or strings, got {v!r}")
    return list(value)


def _hint(key: str, names) -> str:
    close = difflib.get_close_matches(key, names, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _label(swept: Mapping[str, Any]) -> str:
    return "(" + ", ".join(f"{k}={v!r}" for k, v in swept.items()) + ")" if swept else ""


WHERE_VALUES_SHOWN = 12


def _where_value(h) -> str:
    """A value as --where takes it back: every digit that the 1e-12 match needs, or 1/N
    for a long decimal that is the reciprocal of a whole number (as campaign files give
    spacings)."""
    if isinstance(h, float) and not isinstance(h, bool):
        if len(repr(h)) > 8 and 0 < h < 1 and abs(1 / h - round(1 / h)) <= 1e-12 * (1 / h):
            return f"1/{round(1 / h)}"
        return repr(h)
    return str(h)


def _values_text(have: set, value) -> str:
    """A campaign's values of one parameter, numbers in numeric order; beyond
    WHERE_VALUES_SHOWN of them, those nearest to the value asked for (the first twelve in
    text order had hidden them)."""
    numbers = sorted(h for h in have if isinstance(h, (int, float)) and not isinstance(h, bool))
    others = sorted((h for h in have if h not in numbers), key=str)
    ordered = numbers + others
    if len(ordered) <= WHERE_VALUES_SHOWN:
        return ", ".join(_where_value(h) for h in ordered)
    if numbers and isinstance(value, (int, float)) and not isinstance(value, bool):
        near = sorted(sorted(numbers, key=lambda h: abs(h - value))[:WHERE_VALUES_SHOWN])
        return (f"{len(ordered)} values, the {len(near)} nearest to {_where_value(value)}: "
                + ", ".join(_where_value(h) for h in near))
    return (f"{len(ordered)} values, the first {WHERE_VALUES_SHOWN}: "
            + ", ".join(_where_value(h) for h in ordered[:WHERE_VALUES_SHOWN]) + ", ...")


def select_runs(spec: CampaignSpec, where) -> list[Run]:
    """The runs of ``spec`` whose parameters match every ``KEY=VALUE`` of ``where`` (values
    read as in a campaign file: "spacing=1/1340", "self_term=3.8"; numbers compared to 1e-12
    relative). Refused, before anything runs: a malformed item, an unknown parameter, and a
    selection that matches no run (the message lists the values the campaign has)."""
    conditions = []
    if isinstance(where, str):              # one condition, not its characters
        where = [where]
    for item in where:
        key, sep, raw = str(item).partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key or not raw.strip():
            raise CampaignError(f"--where: expected KEY=VALUE, got {item!r}")
        conditions.append((key, raw.strip(), parse_param(key, raw.strip(), "--where")))

    def same(a, b) -> bool:
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
            return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)
        return a == b

    chosen = [r for r in spec.runs if all(same(getattr(r.params, k), v) for k, _, v in conditions)]
    if not chosen:
        for key, raw, value in conditions:
            have = {getattr(r.params, key) for r in spec.runs}
            if not any(same(h, value) for h in have):
                raise CampaignError(f"--where: no run of campaign {spec.name!r} has {key}={raw}; "
                                    f"its values of {key}: {_values_text(have, value)}")
        raise CampaignError(f"--where: no run of campaign {spec.name!r} matches all of "
                            f"{', '.join(f'{k}={r}' for k, r, _ in conditions)}")
    return chosen
