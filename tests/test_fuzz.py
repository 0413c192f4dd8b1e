"""Property-based fuzz of the parameter record and the campaign file (hypothesis).

Any input is either accepted (and then runs, at a tiny size) or refused with a
ParameterError / CampaignError that names a parameter; never another exception, never a
hang. Sizes are kept tiny and example counts bounded so the file runs in CI in well under
a minute (set HYPOTHESIS_PROFILE=long for a longer local search)."""
from __future__ import annotations

import math
import os
import re
import signal
import warnings
from contextlib import contextmanager

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

from tfm import Params, guards, params as P  # noqa: E402
from tfm.campaign import CampaignError, load_spec, spec_from_dict  # noqa: E402
from tfm.campaign.spec import TOP_LEVEL_KEYS  # noqa: E402
from tfm.params import ParameterError  # noqa: E402

FIELDS = Params.field_names()
CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")
settings.register_profile("default", deadline=None, derandomize=CI, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", deadline=None, max_examples=2000,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


@contextmanager
def no_hang(seconds: int):
    """Fail, rather than hang, if one example takes longer than ``seconds``."""
    def alarm(*_):
        raise TimeoutError(f"example took more than {seconds} s")
    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


garbage = st.one_of(
    st.none(), st.booleans(), st.text(max_size=6),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 12, 10 ** 12),
    st.lists(st.integers(0, 3), max_size=2), st.dictionaries(st.text(max_size=2), st.integers(), max_size=1),
    st.sampled_from(["1/64", "1//64", "1/6/4", "1/", "auto", "none", "nan", "-inf", "1e400", " 3 ", "0x1"]),
    st.builds(np.int64, st.integers(-5, 5)), st.builds(np.float32, st.floats(-2, 2)),
)

# plausible values: mostly valid, some just outside the range, all at tiny sizes
PLAUSIBLE = {
    "spacing": st.sampled_from(["1/8", "1/12", "1/16", "1/24", 0.05, 0.1, 0.0, -0.1, 2.0]),
    "alpha": st.floats(-1.5, 3.5),
    "k_th": st.one_of(st.none(), st.floats(-0.01, 0.1)),
    "f_th": st.one_of(st.none(), st.floats(-1e-4, 1e-3)),
    "radius": st.floats(0.0, 2.0),
    "shape": st.sampled_from(P.SHAPES + ("cube",)),
    "kernel": st.sampled_from(P.KERNELS + ("bousinesq",)),
    "self_term": st.floats(-1.0, 6.0),
    "neighbor_rings": st.integers(-1, 4),
    "c_w": st.floats(-0.5, 3.0),
    "operator": st.sampled_from(P.OPERATORS + ("fmm",)),
    "theta": st.floats(0.0, 1.2),
    "layout": st.sampled_from(P.LAYOUTS),
    "jitter": st.floats(-0.1, 0.6),
    "seed": st.integers(-1, 5),
    "max_indent": st.one_of(st.just("auto"), st.floats(0.0, 0.3)),
    "step": st.floats(1e-3, 0.06),
    "snap_rule": st.sampled_from(P.SNAP_RULES + ("all",)),
    "tol": st.sampled_from([1e-12, 1e-8, 1e-5, 1e-3, 0.5]),
    "max_iter": st.integers(0, 400),
    "max_rounds": st.integers(0, 400),
    "max_unload_steps": st.one_of(st.none(), st.integers(0, 200)),
    "preconditioner": st.sampled_from(P.PRECONDITIONERS),
    "extent": st.one_of(st.none(), st.floats(0.0, 0.8)),
    "extent_margin": st.floats(-0.5, 3.0),
    "allow": st.sampled_from(["", "coarse", "coarse,step,tol", "step,tol", "bogus"]),
}
# a field added later gets garbage and its default until someone adds plausible values
VALUE = {name: st.one_of(PLAUSIBLE.get(name, st.just(P._DEFAULTS[name])), garbage) for name in FIELDS}


@st.composite
def param_dicts(draw, garbage_keys=True):
    names = draw(st.lists(st.sampled_from(FIELDS), max_size=8, unique=True))
    values = {name: draw(VALUE[name]) for name in names}
    if garbage_keys and draw(st.booleans()):
        values[draw(st.sampled_from(["alpah", "spacng", "", "x"]))] = 1
    return values


def names_a_parameter(message: str) -> bool:
    """The message names a field, or the unknown key it refuses."""
    if "unknown parameter" in message:
        return True
    return any(re.search(rf"(^|[^a-z_]){re.escape(n)}([^a-z_]|$)", message) for n in FIELDS)


def accept_or_refuse(values):
    """The record and its guards: a Params, or None after a ParameterError naming a parameter."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", P.ParameterWarning)
            p = Params.from_dict(values)
            guards.check(p, memory=False)
        return p
    except ParameterError as exc:
        assert names_a_parameter(str(exc)), f"{type(exc).__name__} names no parameter: {exc}"
        return None


def tiny(p: Params) -> bool:
    return guards.n_springs(p) <= 3000 and p.delta_max / p.step <= 80


@settings(max_examples=400)
@given(param_dicts())
def test_any_record_is_accepted_or_refused_with_a_named_parameter(values):
    with no_hang(20):
        p = accept_or_refuse(values)
    if p is not None:
        assert Params.from_dict(p.to_dict()).run_id == p.run_id           # round trip
        assert Params.from_row({"p_" + k: (math.nan if v is None else v) for k, v in p.to_dict().items()}
                               ).run_id == p.run_id


TINY_RUN = dict(spacing="1/16", shape="paraboloid", k_th=0.02, max_indent=0.05, step=5e-3)


@st.composite
def runnable_dicts(draw):
    """A tiny meaningful run, with up to 4 parameters drawn from their plausible values."""
    names = draw(st.lists(st.sampled_from(sorted(PLAUSIBLE)), max_size=4, unique=True))
    return {**TINY_RUN, **{name: draw(PLAUSIBLE[name]) for name in names}}


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(runnable_dicts())
def test_an_accepted_tiny_record_runs(values):
    from tfm import simulate

    p = accept_or_refuse(values)
    hypothesis.assume(p is not None and tiny(p))
    with no_hang(60), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = simulate(p)
        except ParameterError as exc:          # e.g. a kernel that is not positive definite
            assert names_a_parameter(str(exc)), exc
            return
    curve = res.curve
    assert len(curve) >= 1 and np.isfinite(curve["force"]).all()
    assert res.summary["n_steps"] == len(curve)


# ---- campaign files ----------------------------------------------------------------------
section = st.dictionaries(st.sampled_from(FIELDS + ("alpah",)),
                          st.one_of(VALUE["alpha"], st.lists(VALUE["radius"], max_size=3)), max_size=3)


@st.composite
def campaign_dicts(draw):
    data = {}
    for key in draw(st.lists(st.sampled_from(TOP_LEVEL_KEYS + ("descripton",)), max_size=6, unique=True)):
        if key == "name":
            data[key] = draw(st.one_of(st.sampled_from(["fz", "a.b-c", "../x", ""]), garbage))
        elif key in ("description", "descripton"):
            data[key] = draw(st.one_of(st.text(max_size=5), garbage))
        elif key == "max_runs":
            data[key] = draw(st.one_of(st.integers(-1, 20), garbage))
        elif key == "zip":
            data[key] = draw(st.one_of(st.lists(section, max_size=2), section, garbage))
        else:
            data[key] = draw(st.one_of(section, garbage))
    return data


@settings(max_examples=300)
@given(campaign_dicts())
def test_any_campaign_is_expanded_or_refused_with_a_campaign_error(data):
    with no_hang(20):
        try:
            spec = spec_from_dict(data, source="fuzz.toml")
        except CampaignError as exc:
            message = str(exc)
            assert message.startswith("fuzz.toml"), message
            assert names_a_parameter(message) or any(k in message for k in TOP_LEVEL_KEYS + ("descripton",)), message
            return
    assert len(spec.runs) == len(set(spec.run_ids)) >= 1


@settings(max_examples=100)
@given(st.text(max_size=80))
def test_any_text_as_a_campaign_file_is_read_or_refused(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("fz") / "f.toml"
    path.write_text(text)
    with no_hang(20):
        try:
            load_spec(path)
        except CampaignError as exc:
            assert str(exc).startswith(str(path))
