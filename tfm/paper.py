"""Reproduce every result of the paper: ``python -m tfm.paper [--jobs N] [--quick]``.

Hulikal, Bhattacharya & Lapusta, "A threshold-force model for adhesion and mode I
fracture". Runs the campaigns ``campaigns/paper_*.toml`` through ``tfm.campaign`` (so the
tables land in ``results/<campaign>/`` and an interrupted run resumes), measures each
claim of the paper with ``tfm.analysis``, draws the figures with ``tfm.plots`` into
``results/paper/*.png`` and writes ``results/paper/REPORT.md`` with a table of the
paper's claims beside tfm's values, the wall time and the machine.

``--quick`` runs every campaign at twice the spacing and twice the step into
``results/quick/`` (figures and report in ``results/quick/paper/``, ignored by git): a
check of the pipeline, not of the paper.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd

from . import analysis, theory
from .analysis import fraction_text

REPO = Path(__file__).resolve().parents[1]
CAMPAIGN_DIR = REPO / "campaigns"

# (figure key, campaign file stem), in the order of the report
CAMPAIGNS = (
    ("fig2", "paper_fig2_hertz"),
    ("fig3", "paper_fig3_adhesive"),
    ("fig4", "paper_fig4_alpha0"),
    ("fig5", "paper_fig5_alpha075"),
    ("fig6", "paper_fig6_jkr_scaling"),
    ("kernels", "paper_kernels"),
)


# ---- running ---------------------------------------------------------------------
def _load_toml(path: Path) -> dict:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _coarsen(value, factor: float):
    from .params import parse_number

    x = parse_number(value, "spacing") * factor
    frac = Fraction(x).limit_denominator(4096)
    return f"{frac.numerator}/{frac.denominator}" if abs(float(frac) - x) < 1e-12 else x


def quick_spec(path: Path):
    """The campaign at twice the spacing and twice the step (pipeline check only)."""
    from .campaign import spec_from_dict
    from .params import parse_number

    data = _load_toml(path)
    data["name"] = data["name"] + "_quick"
    tables = [data.get("base", {}), data.get("sweep", {})] + list(data.get("zip", []))
    for table in tables:
        for key in list(table):
            vals = table[key]
            many = isinstance(vals, list)
            vals = vals if many else [vals]
            if key == "spacing":
                vals = [_coarsen(v, 2.0) for v in vals]
            elif key == "step":
                vals = [2.0 * parse_number(v, "step") for v in vals]
            table[key] = vals if many else vals[0]
    return spec_from_dict(data, source=f"{path} (quick)")


@dataclass
class CampaignRun:
    key: str
    name: str
    path: Path
    seconds: float
    n_runs: int
    summary: pd.DataFrame
    curves: pd.DataFrame
    description: str = ""
    computed: int = 0          # runs computed by this invocation (the others were stored)


# Longest first: with --jobs N the campaigns run N at a time, each in one worker process
# (its runs in series, on cores/N threads), so the long ones should start first.
RUN_ORDER = ("fig6", "fig4", "kernels", "fig5", "fig3", "fig2")


def _spec(key: str, quick: bool):
    from .campaign import load_spec

    path = CAMPAIGN_DIR / f"{dict(CAMPAIGNS)[key]}.toml"
    return quick_spec(path) if quick else load_spec(path)


def _run_one(key: str, quick: bool, results_dir: str, quiet: bool) -> tuple[str, float]:
    """Run one campaign through the campaign API (in a worker process when --jobs > 1)."""
    from .campaign import run_campaign

    t0 = time.perf_counter()
    run_campaign(_spec(key, quick), jobs=1, quiet=quiet, results_dir=results_dir)
    return key, time.perf_counter() - t0


def run_all(jobs: int, quick: bool, results_dir: Path, quiet: bool = False) -> dict[str, CampaignRun]:
    """Run (or resume) every paper campaign, then load its tables.

    With ``jobs`` > 1, ``jobs`` campaigns run at once, each in a spawned process with
    cores/jobs Numba threads: the paper's campaigns are few, long and unequal, so this
    balances the cores better than a pool inside each campaign (whose longest run would
    hold one core while the other idles)."""
    from .campaign import load_tables

    from .campaign import CampaignStore

    seconds: dict[str, float] = {}
    specs = {key: _spec(key, quick) for key, _ in CAMPAIGNS}     # validate every file first
    stored = {key: len(CampaignStore.for_spec(spec, results_dir).status(spec).done) for key, spec in specs.items()}
    if not quiet:
        for key in RUN_ORDER:
            print(f"[tfm.paper] {specs[key].name}: {len(specs[key].runs)} runs", file=sys.stderr, flush=True)
    if jobs <= 1:
        for key in RUN_ORDER:
            seconds[key] = _run_one(key, quick, str(results_dir), quiet)[1]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        from .campaign.runner import available_cores

        threads = max(1, available_cores() // jobs)
        saved = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = str(threads)
        try:
            with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
                futures = [pool.submit(_run_one, key, quick, str(results_dir), True) for key in RUN_ORDER]
                for fut in as_completed(futures):
                    key, sec = fut.result()
                    seconds[key] = sec
                    if not quiet:
                        print(f"[tfm.paper] {specs[key].name} done in {sec:.0f} s", file=sys.stderr, flush=True)
        finally:
            if saved is None:
                os.environ.pop("NUMBA_NUM_THREADS", None)
            else:
                os.environ["NUMBA_NUM_THREADS"] = saved
    out = {}
    for key, stem in CAMPAIGNS:
        spec = specs[key]
        summary, curves = load_tables(spec.name, results_dir=results_dir)
        ids = set(spec.run_ids)
        summary = summary[summary["run_id"].isin(ids)].reset_index(drop=True)
        curves = curves[curves["run_id"].isin(ids)].reset_index(drop=True)
        if len(summary) != len(spec.runs):
            raise RuntimeError(f"{spec.name}: {len(spec.runs) - len(summary)} runs failed; see "
                               f"{Path(results_dir) / spec.name / 'failures.parquet'}")
        out[key] = CampaignRun(key, spec.name, CAMPAIGN_DIR / f"{stem}.toml", seconds[key], len(spec.runs),
                               summary, curves, spec.description, computed=len(spec.runs) - stored[key])
    return out


def _curves_by(run: CampaignRun, column: str) -> dict:
    out = {}
    for _, row in run.summary.iterrows():
        out[row[column]] = run.curves[run.curves["run_id"] == row["run_id"]].sort_values("step")
    return out


# ---- the claims --------------------------------------------------------------------
@dataclass
class Claim:
    section: str
    claim: str
    paper: str
    tfm: str
    agrees: str          # "yes", "no", "partly", "n/a"
    note: str = ""


@dataclass
class Analysis:
    claims: list[Claim] = field(default_factory=list)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: dict[str, str] = field(default_factory=dict)
    numbers: dict[str, float] = field(default_factory=dict)


def _fmt(x, digits=4):
    return f"{x:.{digits}g}"


def _dmax(row) -> str:
    return f"δ_max = {row['r_max_indent']:.4g}"


def analyse_fig2(run: CampaignRun, out_dir: Path, res: Analysis) -> None:
    from .plots import plot_hertz_validation

    radius = float(run.summary["p_radius"].iloc[0])
    curves = _curves_by(run, "p_spacing")
    rows = []
    for spacing, curve in sorted(curves.items(), reverse=True):
        e = analysis.hertz_errors(curve, radius, spacing)
        rows.append({"spacing": fraction_text(spacing), **e})
    df = pd.DataFrame(rows)
    res.tables["hertz"] = df
    for r in rows:
        res.claims.append(Claim(
            "Fig. 2", f"Hertz: force at δ_max = {r['indent']:.3g}, spacing {r['spacing']} "
                      f"(a/Δ = {r['contact_radius_over_spacing']:.0f})",
            "“surprisingly good match” (no number)",
            f"{100 * r['force_error']:+.2f} % (worst over δ ≥ δ_max/4: {100 * r['max_abs_force_error']:.2f} %); "
            f"contact radius within {r['max_abs_radius_error_spacings']:.2f} Δ",
            "yes" if abs(r["force_error"]) < 0.01 else "partly"))
    res.figures["fig2"] = "fig2_hertz.png"
    plot_hertz_validation(curves, radius, out_dir / "fig2_hertz.png",
                          title=f"Fig. 2: Hertz validation (F_th = 0, paraboloid R = {radius:g}, "
                                f"δ_max = {run.summary['r_max_indent'].iloc[0]:.3g})")


def analyse_fig3(run: CampaignRun, out_dir: Path, res: Analysis) -> None:
    from .plots import plot_load_unload

    row = run.summary.iloc[0]
    curve = run.curves.sort_values("step")
    spacing, f_th, radius = row["p_spacing"], row["r_f_th"], row["p_radius"]
    k_eff = theory.effective_toughness(f_th, spacing)
    f_jkr = theory.jkr_pull_off(k_eff, radius)
    load = curve[curve.phase == "load"].set_index("indent")["force"]
    unload_df = curve[curve.phase == "unload"]
    unload = unload_df.set_index("indent")["force"]
    common = load.index.intersection(unload.index)
    common = common[common < load.index.max() - 1e-12]
    below = bool((unload[common] < load[common]).all())
    n0 = int(curve[curve.phase == "load"]["n_contact"].iloc[-1])
    first = np.flatnonzero(unload_df["n_snapped"].to_numpy() > 0)[0]
    const_area = bool((unload_df["n_contact"].iloc[:first] == n0).all())
    tensile_before = float(unload_df["force"].iloc[:first].min()) if first > 0 else math.nan
    live = unload_df[unload_df["n_contact"] > 0]
    last_force, last_radius = float(live["force"].iloc[-1]), float(live["contact_radius"].iloc[-1])
    res.numbers.update(fig3_f_max=row["r_pull_off_force"], fig3_jkr=f_jkr)
    res.claims += [
        Claim("Fig. 3", "unloading force below the loading force at every indentation", "yes", str(below),
              "yes" if below else "no"),
        Claim("Fig. 3", "contact area constant until the first snap", "yes",
              f"{const_area} ({first} unloading steps at {n0} springs)", "yes" if const_area else "no"),
        Claim("Fig. 3", "the force turns tensile before the first snap", "yes",
              f"most tensile force before the first snap: {tensile_before:.3g}",
              "yes" if tensile_before < 0 else "no"),
        Claim("Fig. 3", "force and contact area drop to zero from a finite value", "yes",
              f"last step in contact: F = {last_force:.3g}, a = {last_radius:.3g}",
              "yes" if last_force < 0 and last_radius > 0 else "no"),
        Claim("Fig. 3", f"pull-off force, spacing 1/128, F_th = 2e-5, {_dmax(row)}", "(plot only)",
              f"{row['r_pull_off_force']:.4g}; JKR with K_eff = F_th/Δ^1.5 = {k_eff:.4g}: {f_jkr:.4g} "
              f"(ratio {row['r_pull_off_force'] / f_jkr:.3f})", "n/a"),
    ]
    res.figures["fig3"] = "fig3_load_unload.png"
    plot_load_unload(curve, radius, k_ic=k_eff, path=out_dir / "fig3_load_unload.png",
                     title=f"Fig. 3: spacing 1/{1 / spacing:.0f}, F_th = {f_th:g} (α = 0), paraboloid R = {radius:g}, "
                           f"δ_max = {row['r_max_indent']:.3g}; JKR with K_eff = {k_eff:.3g}")


def _refinement(run: CampaignRun, out_dir: Path, res: Analysis, key: str, fig: str, predicted: float) -> None:
    from .plots import plot_refinement

    s = run.summary.sort_values("p_spacing", ascending=False)
    radius = float(s["p_radius"].iloc[0])
    alpha = float(s["p_alpha"].iloc[0])
    k_eff = {row["p_spacing"]: theory.effective_toughness(row["r_f_th"], row["p_spacing"]) for _, row in s.iterrows()}
    fit = analysis.spacing_slope(s["p_spacing"], s["r_pull_off_force"])
    ratios = analysis.convergence_ratios(s["p_spacing"], s["r_pull_off_force"])
    table = pd.DataFrame({"spacing": [fraction_text(x) for x in s["p_spacing"]],
                          "delta_max": s["r_max_indent"].to_numpy(),
                          "F_th": s["r_f_th"].to_numpy(),
                          "K_eff": [k_eff[x] for x in s["p_spacing"]],
                          "F_max": s["r_pull_off_force"].to_numpy(),
                          "F_max/(K_eff^2 R)": s["r_pull_off_force"].to_numpy()
                          / np.array([k_eff[x] ** 2 for x in s["p_spacing"]]) / radius,
                          "a_c/spacing": [theory.jkr_critical_radius(k_eff[x], radius) / x for x in s["p_spacing"]]})
    res.tables[key] = table
    res.tables[key + "_ratios"] = ratios
    res.numbers[key + "_slope"] = fit.exponent
    dm = ", ".join(f"{v:.3g}" for v in sorted(set(s["r_max_indent"])))
    ratio_txt = "; ".join(f"{fraction_text(r.spacing_coarse)}→{fraction_text(r.spacing_fine)}: ×{r.ratio:.3f}"
                          for r in ratios.itertuples())
    if alpha == 0:
        paper = "F_max increases with decreasing Δ (no number); LEFM argument: ×8 per halving (slope −3)"
        agrees = "yes" if fit.exponent < -2.5 else "partly"
    else:
        paper = "F_max independent of Δ (“converges”); LEFM argument: ×1 per halving (slope 0)"
        agrees = "yes" if abs(fit.exponent) < 0.1 else "partly"
    res.claims.append(Claim(fig, f"F_max ratio between spacings, α = {alpha:g} (δ_max = {dm})", paper,
                            f"{ratio_txt}; fitted slope d ln F/d ln Δ = {fit.text(3)} (predicted {predicted:g})",
                            agrees))
    name = f"{key}.png"
    res.figures[key] = name
    thr = (f"F_th = {s['r_f_th'].iloc[0]:g}" if alpha == 0 else f"K_th = {s['p_k_th'].iloc[0]:g}, F_th = K_th A^{alpha:g}")
    plot_refinement(_curves_by(run, "p_spacing"), radius, k_ic=k_eff if alpha == 0 else k_eff[s["p_spacing"].iloc[0]],
                    path=out_dir / name, predicted_slope=predicted,
                    title=f"{fig}: α = {alpha:g}, {thr}, paraboloid R = {radius:g}, δ_max = {dm}; "
                          f"slope d ln F_max/d ln Δ = {fit.exponent:.3f}")


def analyse_fig6(run: CampaignRun, out_dir: Path, res: Analysis) -> None:
    from .plots import plot_jkr_scaling

    s = run.summary
    f = s["r_pull_off_force"]
    k_rows = s[s["p_radius"] == 1.0].sort_values("p_k_th")
    k_top = float(s["p_k_th"].max())
    r_rows = s[s["p_k_th"] == k_top].sort_values("p_radius")
    kpos = k_rows[k_rows["p_k_th"] > 0]
    k_fit = analysis.fit_power_law(kpos["p_k_th"], kpos["r_pull_off_force"])
    r_fit = analysis.fit_power_law(r_rows["p_radius"], r_rows["r_pull_off_force"])
    x = (k_rows["p_k_th"] ** 2 * k_rows["p_radius"]).to_numpy()
    coef_fit = analysis.fit_line(x, k_rows["r_pull_off_force"].to_numpy(), through_origin=True)
    all_pos = s[s["p_k_th"] > 0]
    coef_all = analysis.fit_line((all_pos["p_k_th"] ** 2 * all_pos["p_radius"]).to_numpy(),
                                 all_pos["r_pull_off_force"].to_numpy(), through_origin=True)
    table = pd.DataFrame({"k_th": s["p_k_th"], "radius": s["p_radius"], "spacing": [fraction_text(v) for v in s["p_spacing"]],
                          "delta_max": s["r_max_indent"], "F_max": f,
                          "F_max/(k^2 R)": [fm / (k ** 2 * r) if k > 0 else math.nan
                                            for fm, k, r in zip(f, s["p_k_th"], s["p_radius"])],
                          "a_c/spacing": [theory.jkr_critical_radius(k, r) / h if k > 0 else 0.0
                                          for k, r, h in zip(s["p_k_th"], s["p_radius"], s["p_spacing"])]})
    res.tables["fig6"] = table.sort_values(["radius", "k_th"]).reset_index(drop=True)
    res.numbers.update(beta=k_fit.exponent, beta_half=k_fit.half_width, gamma=r_fit.exponent,
                       gamma_half=r_fit.half_width, coefficient=coef_fit.slope, coefficient_half=coef_fit.half_width,
                       coefficient_all=coef_all.slope)
    sp = fraction_text(float(s["p_spacing"].iloc[0]))
    kd = ", ".join(f"{v:.3g}" for v in kpos["r_max_indent"])
    rd = ", ".join(f"{v:.3g}" for v in r_rows["r_max_indent"])
    res.claims += [
        Claim("Fig. 6a", f"exponent β of F_max ∝ K_th^β (R = 1, Δ = {sp}, K_th = "
                         f"{', '.join(f'{v:g}' for v in kpos['p_k_th'])}; δ_max = {kd})",
              "2", f"{k_fit.text(3)} (95 % CI, {k_fit.n} points)", "yes" if k_fit.contains(2.0) or abs(k_fit.exponent - 2) < 0.05 else "no"),
        Claim("Fig. 6b", f"exponent γ of F_max ∝ R^γ (K_th = {k_top:g}, Δ = {sp}, R = "
                         f"{', '.join(f'{v:g}' for v in r_rows['p_radius'])}; δ_max = {rd})",
              "1", f"{r_fit.text(3)} (95 % CI, {r_fit.n} points)", "yes" if r_fit.contains(1.0) or abs(r_fit.exponent - 1) < 0.05 else "no"),
        Claim("Fig. 6", f"coefficient c in F_max = c K_th² R at Δ = {sp} (least squares through the origin, R = 1 series)",
              "7.6 (JKR/LEFM theory: 3π²/4 = 7.402)",
              f"{coef_fit.text(3)}; over all {len(all_pos)} adhesive runs: {coef_all.slope:.3f}; "
              f"vs paper {100 * (coef_fit.slope / theory.PAPER_COEFFICIENT - 1):+.1f} %, "
              f"vs theory {100 * (coef_fit.slope / theory.JKR_COEFFICIENT - 1):+.1f} %",
              "yes" if abs(coef_fit.slope / theory.PAPER_COEFFICIENT - 1) < 0.05 else "no"),
    ]
    res.figures["fig6"] = "fig6_jkr_scaling.png"
    plot_jkr_scaling(k_rows.assign(k_th=k_rows["p_k_th"], radius=k_rows["p_radius"], f_max=k_rows["r_pull_off_force"]),
                     r_rows.assign(k_th=r_rows["p_k_th"], radius=r_rows["p_radius"], f_max=r_rows["r_pull_off_force"]),
                     k_fit, r_fit, coef_fit, out_dir / "fig6_jkr_scaling.png",
                     title=f"Fig. 6: α = 0.75, spacing {sp}, paraboloid; δ_max per run in REPORT.md")


PREDICTED_ALPHA = {"boussinesq": ("0.75", 0.75), "local": ("1", 1.0), "neighbors": ("not stated", 0.75)}


def analyse_kernels(run: CampaignRun, out_dir: Path, res: Analysis) -> None:
    from .plots import plot_kernel_study

    s = run.summary
    slopes = analysis.kernel_slopes(s)
    crossings = {}
    for kernel, g in slopes.groupby("p_kernel"):
        crossings[kernel] = analysis.convergent_alpha(g["p_alpha"], g["slope"])
    res.tables["kernel_slopes"] = slopes
    res.tables["kernels"] = pd.DataFrame({
        "kernel": s["p_kernel"], "alpha": s["p_alpha"], "k_th": s["p_k_th"], "spacing": [fraction_text(v) for v in s["p_spacing"]],
        "delta_max": s["r_max_indent"], "F_max": s["r_pull_off_force"]})
    for kernel, zc in crossings.items():
        paper, predicted = PREDICTED_ALPHA.get(kernel, ("?", math.nan))
        g = slopes[slopes["p_kernel"] == kernel]
        ok = zc.ci_low <= predicted <= zc.ci_high or abs(zc.alpha - predicted) < 0.05
        extra = " (our theory for fixed m rings: 0.75, see below)" if kernel == "neighbors" else ""
        res.claims.append(Claim(
            "Sec. 3.2", f"convergent α, {kernel} kernel (slopes over Δ = {g['spacings'].iloc[0]} at α = "
                        f"{', '.join(f'{a:g}' for a in g['p_alpha'])})",
            paper + extra, f"{zc.text(3)} (95 % CI); d slope/dα = {zc.gradient:.2f} (theory 4)",
            ("yes" if ok else "no") if kernel != "neighbors" else ("n/a; theory " + ("agrees" if ok else "disagrees"))))
        res.numbers[f"alpha_{kernel}"] = zc.alpha
    res.figures["kernels"] = "kernels.png"
    plot_kernel_study(s, slopes, crossings, out_dir / "kernels.png",
                      title="Sec. 3.2: kernel study (paraboloid R = 1); δ_max per run in REPORT.md")


# ---- the report ------------------------------------------------------------------
def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = os.getloadavg()
    except OSError:
        load = (math.nan,) * 3
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    return {"nproc": cores, "cpu": cpu, "host": platform.node(), "python": platform.python_version(),
            "load": load}


def _md_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for _, row in df.iterrows():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(format(v, floatfmt) if isinstance(v, (float, np.floating)) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_report(path: Path, runs: dict[str, CampaignRun], res: Analysis, wall: float, jobs: int,
                 start_machine: dict, quick: bool) -> None:
    m = machine()
    total_runs = sum(r.n_runs for r in runs.values())
    computed = sum(r.computed for r in runs.values())
    run_seconds = sum(float(r.summary["r_wall_time"].sum()) for r in runs.values())
    lines = [
        "# tfm reproduces the threshold-force paper: report",
        "",
        "Generated by `make paper` (`python -m tfm.paper --jobs N`) on "
        f"{_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}. Do not edit by hand: rerun `make paper`.",
        "Paper: Hulikal, Bhattacharya & Lapusta, *A threshold-force model for adhesion and mode I fracture*.",
        "Units are the paper's (E* = 1/π, C_ij = 1/r_ij, self term 3.8/Δ). Every body is a paraboloid of",
        "radius R (the paper's sphere at the small depths where Hertz and JKR apply). Every F_max is",
        "quoted with its preload δ_max (see the tables), and every preload is deeper than the JKR",
        "critical radius needs: sqrt(R δ_max) ≥ 1.2 a_c (shared/PHYSICS.md, “Loading depth matters”).",
        "",
    ]
    if quick:
        lines += ["**QUICK MODE: every spacing and step doubled. These numbers check the pipeline, "
                  "not the paper.**", ""]
    lines += [
        "## Run",
        "",
        f"- wall time of `make paper`: **{wall / 60:.1f} min** ({wall:.0f} s) with `--jobs {jobs}`, "
        f"{total_runs} runs in {len(runs)} campaigns, {computed} of them computed by this invocation "
        f"({'a full run from empty result folders' if computed == total_runs else 'the rest resumed from results/'}); "
        f"the runs' own compute time adds up to {run_seconds:.0f} s.",
        f"- machine: {m['nproc']} cores, {m['cpu']}, Python {m['python']}; load average "
        f"{start_machine['load'][0]:.1f} at the start and {m['load'][0]:.1f} at the end "
        "(a load above the core count means other work shared the machine and the time is pessimistic).",
        "- campaigns (results in `results/<name>/`; `make paper` again resumes and only analyses):",
        "",
        "| campaign | runs | computed now | wall time (s) | what |",
        "|---|---|---|---|---|",
    ]
    for r in runs.values():
        rel = r.path.relative_to(REPO) if r.path.is_relative_to(REPO) else r.path
        lines.append(f"| [`{r.name}`](../../{rel}) | {r.n_runs} | {r.computed} | {r.seconds:.0f} | {r.description} |")
    lines += ["", "## The paper's claims beside tfm's values", "",
              "| where | claim | paper | tfm | agrees |", "|---|---|---|---|---|"]
    for c in res.claims:
        lines.append(f"| {c.section} | {c.claim} | {c.paper} | {c.tfm} | {c.agrees} |")
    lines += ["", "Exponent intervals are 95 % Student-t intervals of an ordinary least-squares fit in "
              "log-log space (`tfm.analysis`); with few points they are wide, and the stated physics "
              "tolerances in `tests/test_scaling*.py` are the regression targets.", ""]
    lines += DISCUSSION(res)
    sections = [
        ("fig2", "Figure 2: Hertz validation", "hertz"),
        ("fig3", "Figure 3: adhesive load–unload at spacing 1/128, F_th = 2e-5", None),
        ("fig4", "Figure 4: α = 0 (fixed F_th) is discretization dependent", "fig4"),
        ("fig5", "Figure 5: α = 0.75 converges", "fig5"),
        ("fig6", "Figure 6: F_max ∝ K_th² R", "fig6"),
        ("kernels", "Section 3.2: the convergent α depends on the kernel", "kernel_slopes"),
    ]
    for key, title, table in sections:
        if key not in res.figures:
            continue
        lines += [f"## {title}", "", f"![{title}]({res.figures[key]})", ""]
        if table and table in res.tables:
            lines += [_md_table(res.tables[table]), ""]
        if key in ("fig4", "fig5") and key + "_ratios" in res.tables:
            lines += [_md_table(res.tables[key + "_ratios"]), ""]
        if key == "kernels":
            lines += ["Every run of the kernel study:", "", _md_table(res.tables["kernels"]), ""]
    path.write_text("\n".join(lines) + "\n")


def DISCUSSION(res: Analysis) -> list[str]:
    """The disagreements and what we believe causes them (filled from the measured numbers)."""
    n = res.numbers
    out = ["## Where tfm and the paper disagree, and why", ""]
    if "coefficient" in n:
        c = n["coefficient"]
        trend = ""
        for key in ("fig5", "fig4"):
            t = res.tables.get(key)
            if t is not None:
                trend += (f" {'Fig. 5' if key == 'fig5' else 'Fig. 4'}: " + ", ".join(
                    f"{v:.2f} at a_c/Δ = {N:.0f}" for v, N in zip(t["F_max/(K_eff^2 R)"], t["a_c/spacing"])) + ";")
        out += [
            f"- **The coefficient.** tfm measures F_max = {c:.2f} K_th² R at Δ = 1/256 "
            f"({100 * (c / theory.PAPER_COEFFICIENT - 1):+.1f} % from the paper's 7.6, "
            f"{100 * (c / theory.JKR_COEFFICIENT - 1):+.1f} % from JKR/LEFM's 3π²/4 = 7.40): within the "
            "5 % the issue asks, but above both. The coefficient F_max/(K_eff² R) is not converged at "
            "the paper's spacing; it falls slowly as the JKR radius a_c grows in units of the spacing"
            f" ({trend.strip().rstrip(';')}). "
            "So at Δ = 1/256 it depends on K_th and R through a_c/Δ (Fig. 6 table). It decreases "
            "towards the JKR value from above, and the paper's 7.6 lies between our 1/256 values "
            "and 7.40; if the trend goes on, a finer effective resolution would reach 7.6 (we ran "
            "nothing finer than 1/256 to confirm it). The paper states neither its preload, nor its step, "
            "nor its fit range, all of which move this number by ~1 %. We believe the excess is "
            "the crack-tip discretization: the threshold acts on the force of one spring of width "
            "Δ, and the self term 3.8 (Love's value at the centre of a square is 3.53) sets how "
            "much of the tip field that spring sees. We did not tune anything to match.",
        ]
    if "gamma" in n:
        out += [
            f"- **The exponents at fixed Δ.** β = {n['beta']:.3f} ± {n['beta_half']:.3f} and "
            f"γ = {n['gamma']:.3f} ± {n['gamma_half']:.3f}: their 95 % intervals exclude 2 and 1 "
            "by a little, for the same reason. At fixed Δ a larger K_th or R means a larger a_c/Δ "
            "and so a smaller coefficient, which bends the log-log line. In the continuum the "
            "model scales exactly as JKR; the discrete model at fixed spacing does so to 1–2 % "
            "in the exponent over the ranges of Fig. 6.",
        ]
    if "fig5_slope" in n:
        out += [
            f"- **Convergence at α = 0.75.** The fitted slope d ln F_max/d ln Δ is "
            f"{n['fig5_slope']:+.3f}, not 0: F_max still falls by 3–4 % per halving at "
            "1/64–1/256 (the same unconverged coefficient). The paper calls this converged; "
            "against α = 0 (slope near −3) it is, but it is not spacing-independent to better "
            "than a few per cent per halving at these spacings.",
        ]
    if "alpha_boussinesq" in n:
        out += [
            f"- **The convergent α, Boussinesq.** The kernel study finds α* = {n['alpha_boussinesq']:.3f}, "
            "slightly below 0.75 with an interval that excludes it: it runs at 1/32–1/128, where "
            "a_c/Δ is 8–49 and the unconverged coefficient adds about +0.06 to every slope "
            "(Fig. 5), shifting the zero crossing down by 0.06/4 ≈ 0.015. Figs. 4 and 5 at the "
            "paper's spacings give slopes close to 4α − 3 at α = 0 and 0.75.",
        ]
    if "alpha_local" in n:
        out += [
            f"- **The local kernel.** Its convergent α is {n['alpha_local']:.3f}, not exactly 1: the "
            "discrete pull-off exceeds the exact Winkler limit π c_w K_th² R by a first-order "
            "term (the outermost springs hold the threshold force until the step at which they "
            "snap: +8.8 %, +3.7 %, +1.5 % at 1/32, 1/64, 1/128 for α = 1), which tilts every "
            "slope by a few hundredths. The limit itself is confirmed.",
        ]
    if "alpha_neighbors" in n:
        out += [
            f"- **The neighbors kernel.** Its convergent α is {n['alpha_neighbors']:.3f}. The paper "
            "says only that the scaling “depends on the kernel”. With a fixed number m of rings, "
            "every compliance is (a fixed lattice stencil)/Δ, so the kernel acts as a foundation "
            "whose compliance per unit area is ∝ Δ, and F_max ∝ Δ σ_th² R ∝ Δ^(4α−3): the same "
            "exponent as Boussinesq, for a different reason (the prefactor is not the smooth "
            "Winkler one: the contact edge has no smooth field on the scale of m Δ). A cutoff "
            "fixed in physical length (m ∝ 1/Δ) would instead behave like the local kernel (α = 1).",
        ]
    out.append("")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tfm.paper", description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1, help="parallel runs (process pool); default 1")
    ap.add_argument("--quick", action="store_true", help="twice the spacing and step: a pipeline check")
    ap.add_argument("--results-dir", default=None, help="campaign tables (default results, or results/quick)")
    ap.add_argument("--out", default=None, help="figures and REPORT.md (default results/paper, or results/quick/paper)")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    start = machine()
    results_dir = Path(args.results_dir or ("results/quick" if args.quick else "results"))
    out_dir = Path(args.out or ("results/quick/paper" if args.quick else "results/paper"))
    out_dir.mkdir(parents=True, exist_ok=True)
    if args.quick and args.results_dir is None:
        (results_dir / ".gitignore").write_text("# python -m tfm.paper --quick: scratch output\n*\n")
    runs = run_all(args.jobs, args.quick, results_dir, quiet=args.quiet)
    res = Analysis()
    analyse_fig2(runs["fig2"], out_dir, res)
    analyse_fig3(runs["fig3"], out_dir, res)
    _refinement(runs["fig4"], out_dir, res, "fig4", "Fig. 4", -3.0)
    _refinement(runs["fig5"], out_dir, res, "fig5", "Fig. 5", 0.0)
    analyse_fig6(runs["fig6"], out_dir, res)
    analyse_kernels(runs["kernels"], out_dir, res)
    wall = time.perf_counter() - t0
    write_report(out_dir / "REPORT.md", runs, res, wall, args.jobs, start, args.quick)
    print(_md_table(pd.DataFrame([c.__dict__ for c in res.claims])[["section", "claim", "tfm", "agrees"]]))
    print(f"[tfm.paper] wrote {out_dir / 'REPORT.md'} and {len(res.figures)} figures in {wall:.0f} s",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
