"""The continuum-limit fit on real runs (slow tier: ``make test-slow``, about a minute).

Runs the coarse end of campaigns/limit_sphere.toml (a_c/spacing <= 32, Love's centre
self term, main preload) through tfm.campaign into a temporary folder, or reuses the
stored runs of ``make limit`` with TFM_SLOW_RESULTS=results. It checks that the fit is
stable, not what the limit is: the result is what it is (issue 12).
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from tfm import theory
from tfm.analysis import fit_limit
from tfm.campaign import load_spec, run_campaign
from tfm.paper.limit import spec_ratio, split_preloads, stored_points

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
MAX_RATIO = 32.0          # seven spacings, a_c/spacing = 8 .. 32


@pytest.fixture(scope="module")
def points(tmp_path_factory):
    spec = load_spec(REPO / "campaigns" / "limit_sphere.toml")
    main = min(r.params.delta_max for r in spec.runs)
    sub = dataclasses.replace(spec, runs=tuple(
        r for r in spec.runs if spec_ratio(r.params) <= MAX_RATIO * (1 + 1e-9)
        and abs(r.params.self_term - theory.SELF_TERM_CENTRE) < 1e-3 and r.params.delta_max == main))
    reuse = os.environ.get("TFM_SLOW_RESULTS")
    results = Path(reuse) if reuse else tmp_path_factory.mktemp("limit")
    if not reuse:
        run_campaign(sub, jobs=min(2, os.cpu_count() or 1), quiet=True, results_dir=results)
    pts, _ = split_preloads(stored_points("paraboloid", sub, results))
    assert len(pts) == len(sub.runs), "every run of the coarse end is stored"
    return pts.sort_values("ratio")


def test_limit_is_stable_when_refitted_without_any_one_point(points):
    x, y = points["ratio"].to_numpy(), points["y"].to_numpy()
    full = fit_limit(x, y)
    assert full.p > 0 and not full.p_open[0], "the data pin a positive convergence exponent"
    for i in range(x.size):
        keep = np.arange(x.size) != i
        part = fit_limit(x[keep], y[keep])
        assert part.y_inf_low <= full.y_inf <= part.y_inf_high, (i, full.text(), part.text())
        assert part.p > 0


def test_coefficient_falls_towards_its_limit(points):
    """The coarse points lie above the fitted limit and the fit passes through them."""
    full = fit_limit(points["ratio"], points["y"])
    assert np.all(points["y"].to_numpy() > full.y_inf_low)
    # the residuals are the staircase scatter: a few times below the trend's own size
    trend = points["y"].max() - points["y"].min()
    assert full.sigma < 0.2 * trend
