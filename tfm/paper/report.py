"""The paper report: figures and ``results/paper/REPORT.md`` from the claims.

Every number in the text comes from the campaigns' tables (through ``claims``) or from
the named constants of ``tfm.theory``; nothing is typed in by hand.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
from pathlib import Path

import numpy as np
import pandas as pd

from .. import theory
from ..analysis import fraction_text
from .claims import Finding
from .run import REPO

# the timing of the last make paper that computed every run (kept when later runs only resume)
FULL_RUN_RECORD = "last_full_run.json"

# (figure key, section title, table to print), in the order of the report
SECTIONS = (
    ("fig2", "Figure 2: Hertz validation", "hertz"),
    ("fig3", "Figure 3: adhesive load–unload", None),
    ("fig4", "Figure 4: α = 0 (fixed F_th) is discretization dependent", "fig4"),
    ("fig5", "Figure 5: α = 0.75 converges", "fig5"),
    ("fig6", "Figure 6: F_max ∝ K_th² R", "fig6"),
    ("kernels", "Section 3.2: the convergent α depends on the kernel", "kernel_slopes"),
)


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


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def md_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for _, row in df.iterrows():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(format(v, floatfmt) if isinstance(v, (float, np.floating)) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def merge(findings: dict[str, Finding]) -> Finding:
    """All claims, tables and numbers in one Finding (report order)."""
    out = Finding()
    for f in findings.values():
        out.claims += f.claims
        out.tables.update(f.tables)
        out.numbers.update(f.numbers)
    return out


def draw_figures(findings: dict[str, Finding], out_dir: Path) -> dict[str, str]:
    names = {}
    for key, f in findings.items():
        if f.figure is not None:
            f.figure.draw(**f.figure.kwargs, path=out_dir / f.figure.name)
            names[key] = f.figure.name
    return names


def _pct_range(lo: float, hi: float, digits: int = 1) -> str:
    a, b = f"{100 * lo:.{digits}f}", f"{100 * hi:.{digits}f}"
    return f"{a} %" if a == b else f"{a}–{b} %"


def _spacings(pair) -> str:
    return f"{fraction_text(pair[0])}–{fraction_text(pair[1])}"


def discussion(n: dict, limit_line: str | None = None) -> list[str]:
    """The disagreements and what we believe causes them (every number from ``n``)."""
    out = ["## Where tfm and the paper disagree, and why", ""]
    if "coefficient" in n:
        c = n["coefficient"]
        trend = "; ".join(
            f"{name}: " + ", ".join(f"{v:.2f} at a_c/Δ = {N:.0f}" for v, N in zip(t["F_max/(K_eff^2 R)"], t["a_c/spacing"]))
            for name, t in (("Fig. 5", n.get("_fig5_table")), ("Fig. 4", n.get("_fig4_table"))) if t is not None)
        step = n.get("fig6_step_bound", math.nan)
        step_txt = (f"F_max, sampled once per step, can miss the top of the force curve by up to "
                    f"{100 * step:.1f} % (the rise of the force over one step just before the pull-off, "
                    "largest over the Fig. 6 curves)" if math.isfinite(step) else "the step moves it too")
        follow = (limit_line if limit_line else
                  "`make limit` measures where the trend ends (see “Beyond the paper”).")
        out += [
            f"- **The coefficient.** tfm measures F_max = {c:.2f} K_th² R at Δ = {fraction_text(n['fig6_spacing'])} "
            f"({100 * (c / theory.PAPER_COEFFICIENT - 1):+.1f} % from the paper's {theory.PAPER_COEFFICIENT:g}, "
            f"{100 * (c / theory.JKR_COEFFICIENT - 1):+.1f} % from JKR/LEFM's 3π²/4 = {theory.JKR_COEFFICIENT:.2f}). "
            "The coefficient F_max/(K_eff² R) is not converged at the paper's spacing; it falls slowly as the "
            f"JKR radius a_c grows in units of the spacing ({trend}). So at one spacing it depends on K_th and R "
            f"through a_c/Δ (Fig. 6 table: a_c/Δ = {n['fig6_ac_range'][0]:.0f}–{n['fig6_ac_range'][1]:.0f}). "
            f"{follow} The paper states neither its preload, nor its step, nor its fit range; {step_txt}. "
            "We believe the excess is the crack-tip discretization: the threshold acts on the force of one "
            f"spring of width Δ, and the self term {theory.PAPER_SELF_TERM:g} (Love's value at the centre of "
            f"a square is {theory.SELF_TERM_CENTRE:.4f}) sets how much of the tip field that spring sees. "
            "We did not tune anything to match.",
        ]
    if "gamma" in n:
        dev = (abs(n["beta"] / 2 - 1), abs(n["gamma"] - 1))
        out += [
            f"- **The exponents at fixed Δ.** β = {n['beta']:.3f} ± {n['beta_half']:.3f} and "
            f"γ = {n['gamma']:.3f} ± {n['gamma_half']:.3f}"
            + (": their 95 % intervals exclude 2 and 1 by a little, for the same reason."
               if (abs(n['beta'] - 2) > n['beta_half'] and abs(n['gamma'] - 1) > n['gamma_half']) else ".")
            + " At fixed Δ a larger K_th or R means a larger a_c/Δ and so a smaller coefficient, which bends "
            "the log-log line. In the continuum the model scales exactly as JKR; the discrete model at fixed "
            f"spacing does so to {_pct_range(min(dev), max(dev), 0)} in the exponent over the ranges of Fig. 6.",
        ]
    if "fig5_slope" in n:
        lo, hi = n["fig5_drop_per_halving"]
        out += [
            f"- **Convergence at α = 0.75.** The fitted slope d ln F_max/d ln Δ is "
            f"{n['fig5_slope']:+.3f}, not 0: F_max still falls by {_pct_range(lo, hi, 1)} per halving at "
            f"{_spacings(n['fig5_spacings'])} (the same unconverged coefficient). The paper calls this "
            "converged; against α = 0 (slope near −3) it is, but it is not spacing-independent to better "
            "than a few per cent per halving at these spacings.",
        ]
    if "alpha_boussinesq" in n:
        txt = (f"- **The convergent α, Boussinesq.** The kernel study finds α* = {n['alpha_boussinesq']:.3f}: it "
               f"runs at {_spacings(n['boussinesq_spacings'])}, where a_c/Δ is "
               f"{n['boussinesq_ac_range'][0]:.0f}–{n['boussinesq_ac_range'][1]:.0f}")
        if "fig5_slope" in n:
            shift = n["fig5_slope"] / n["alpha_boussinesq_gradient"]
            txt += (f", and the unconverged coefficient adds about {n['fig5_slope']:+.3f} to every slope (Fig. 5), "
                    f"shifting the zero crossing by {-shift:+.3f} (that slope over d slope/dα = "
                    f"{n['alpha_boussinesq_gradient']:.2f})")
            if "fig4_slope" in n:
                txt += (". " + _slopes_against_theory(n))
        txt += "."
        out += [txt]
    if "alpha_local" in n:
        excess = n.get("local_winkler_excess", [])
        ex = (", ".join(f"{100 * e:+.1f} %" for _, e in excess) + " at "
              + ", ".join(fraction_text(h) for h, _ in excess) + " for α = 1") if excess else ""
        out += [
            f"- **The local kernel.** Its convergent α is {n['alpha_local']:.3f}, not exactly 1: the "
            "discrete pull-off exceeds the exact Winkler limit π c_w K_th² R by a first-order "
            f"term (the outermost springs hold the threshold force until the step at which they snap: {ex}), "
            "which tilts every slope by a few hundredths." + _local_limit_text(excess),
        ]
    if "alpha_neighbors" in n:
        out += [
            f"- **The neighbors kernel.** Its convergent α is {n['alpha_neighbors']:.3f}. The paper "
            "says only that the scaling “depends on the kernel”. With a fixed number m of rings, "
            "every compliance is (a fixed lattice stencil)/Δ, so the kernel acts as a foundation "
            "whose compliance per unit area is ∝ Δ, and F_max ∝ Δ σ_th² R ∝ Δ^(4α−3): by this argument "
            "the same exponent as Boussinesq, for a different reason (the prefactor is not the smooth "
            "Winkler one: the contact edge has no smooth field on the scale of m Δ). "
            + ("The fit agrees with α = 0.75 (claims table). " if n.get("alpha_neighbors_agrees") else
               "The fit does not give 0.75 here (claims table): at these spacings the argument is not borne "
               "out, or the few rings' edge effects are not yet small. ")
            + "A cutoff fixed in physical length (m ∝ 1/Δ) would instead behave like the local kernel (α = 1).",
        ]
    out.append("")
    return out


def _slopes_against_theory(n: dict) -> str:
    """Figs. 4 and 5's fitted slopes against 4α − 3, in words that follow the fits (a quick
    run's Fig. 4 slope of −2.6 ± 1.6 was called close to −3)."""
    parts, close = [], []
    for key, fig in (("fig4", "Fig. 4"), ("fig5", "Fig. 5")):
        if f"{key}_slope" not in n:
            continue
        slope, half, want = n[f"{key}_slope"], n.get(f"{key}_slope_half", math.nan), n[f"{key}_slope_predicted"]
        parts.append(f"{fig} {slope:+.3f}" + (f" ± {half:.3f}" if math.isfinite(half) else "") + f" against {want:g}")
        close.append(math.isfinite(half) and half < 0.5 and abs(slope - want) <= max(half, 0.1))
    verdict = ("close to 4α − 3 at α = 0 and 0.75" if all(close) else
               "not all close to 4α − 3 with these spacings and intervals")
    return f"The fitted slopes are {'; '.join(parts)}: {verdict}"


def _local_limit_text(excess) -> str:
    """What the local kernel's excess over the Winkler limit says about the limit (it was
    called confirmed whatever the numbers)."""
    values = [e for _, e in excess]
    if len(values) >= 2 and all(abs(b) < abs(a) for a, b in zip(values, values[1:])):
        return (f" The excess falls as the spacing shrinks, to {100 * values[-1]:+.1f} % at the finest: the runs "
                "approach the Winkler limit (tests/test_physics.py checks the discrete pull-off exactly and its "
                "convergence).")
    return " The excess does not fall steadily with the spacing in these runs, so they do not show the limit."


#: the preload that shows the JKR pull-off: sqrt(R delta_max) >= this x a_c (docs/physics.md, §6)
PRELOAD_OVER_AC = 1.2


def preload_ratios(summary: pd.DataFrame) -> pd.Series:
    """sqrt(R δ_max) / a_c of each adhesive run (F_th > 0), a_c the JKR critical radius of
    its effective toughness."""
    ad = summary[summary["r_f_th"] > 0]
    k = theory.effective_toughness(ad["r_f_th"].to_numpy(), ad["p_spacing"].to_numpy())
    a_c = np.array([theory.jkr_critical_radius(kk, r) for kk, r in zip(k, ad["p_radius"])])
    return pd.Series(np.sqrt(ad["p_radius"].to_numpy() * ad["r_max_indent"].to_numpy()) / a_c, index=ad.index)


def _preload_text(runs: dict) -> str:
    """Whether every adhesive preload is as deep as the JKR pull-off needs, from the tables
    (it was a sentence typed in, and false for some runs)."""
    short, smallest, n = [], math.inf, 0
    for r in runs.values():
        ratios = preload_ratios(r.summary)
        n += len(ratios)
        if len(ratios):
            smallest = min(smallest, float(ratios.min()))
        for i in ratios.index[ratios < PRELOAD_OVER_AC]:
            row = r.summary.loc[i]
            short.append(f"{r.name} ({row['p_kernel']} kernel, α = {row['p_alpha']:g}, Δ = "
                         f"{fraction_text(row['p_spacing'])}: {ratios[i]:.3f})")
    if not n:
        return ""
    if not short:
        return (f"Every adhesive preload is deeper than the JKR critical radius needs: sqrt(R δ_max) ≥ "
                f"{PRELOAD_OVER_AC:g} a_c (docs/physics.md, §6); the smallest is {smallest:.3f} a_c.")
    return (f"Every adhesive preload but {len(short)} of {n} is deeper than the JKR critical radius needs, "
            f"sqrt(R δ_max) ≥ {PRELOAD_OVER_AC:g} a_c (docs/physics.md, §6); below it: {'; '.join(short)}.")


def _flagged_text(runs: dict) -> str:
    """The runs whose summary carries a warning (a flag), which the claims use like any other."""
    flagged = {r.name: r.summary[r.summary["r_warnings"].fillna("") != ""] for r in runs.values()}
    flagged = {name: f for name, f in flagged.items() if len(f)}
    if not flagged:
        return "No run is flagged (no warnings in any summary)."
    parts = [f"{name}: {len(f)} ({'; '.join(sorted(set(f['r_warnings'])))[:300]})" for name, f in flagged.items()]
    return (f"**Flagged runs** (their numbers are used in the claims below like the others; check them): "
            f"{', '.join(parts)}.")


def _link(target: Path, report: Path) -> str:
    """A Markdown link to ``target`` from the report's folder (which --out may move)."""
    return Path(os.path.relpath(Path(target).resolve(), Path(report).resolve().parent)).as_posix()


def write_report(path: Path, runs: dict, res: Finding, figures: dict[str, str], wall: float, jobs: int,
                 start_machine: dict, quick: bool, limit_line: str | None = None,
                 results_dir: Path | str = "results") -> None:
    m = machine()
    total_runs = sum(r.n_runs for r in runs.values())
    computed = sum(r.computed for r in runs.values())
    run_seconds = sum(float(r.summary["r_wall_time"].sum()) for r in runs.values())
    lines = [
        "# tfm reproduces the threshold-force paper: report",
        "",
        ("Generated by `tfm paper --quick` on " if quick else "Generated by `make paper` (`tfm paper --jobs N`) on ")
        + f"{_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}. Do not edit by hand: rerun "
        + ("`tfm paper --quick`." if quick else "`make paper`."),
        "Paper: Hulikal, Bhattacharya & Lapusta, *A threshold-force model for adhesion and mode I fracture*.",
        f"Units are the paper's (E* = 1/π, C_ij = 1/r_ij, self term {theory.PAPER_SELF_TERM:g}/Δ). Every body is a "
        "paraboloid of",
        "radius R (the paper's sphere at the small depths where Hertz and JKR apply). Every F_max is",
        "quoted with its preload δ_max (see the tables).",
        _preload_text(runs),
        "",
        "Beyond the paper: [the continuum limit of the pull-off coefficient]"
        f"({_link(REPO / 'results' / 'limit' / 'REPORT.md', path)}) (`make limit`).",
        "",
    ]
    if quick:
        lines += ["**QUICK MODE: every spacing and step doubled. These numbers check the pipeline, "
                  "not the paper.**", ""]
    now = {"date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"), "wall": wall, "jobs": jobs, "runs": total_runs,
           "run_seconds": run_seconds, "load_start": start_machine["load"][0], "load_end": m["load"][0],
           "cpu": m["cpu"], "nproc": m["nproc"]}
    record = path.with_name(FULL_RUN_RECORD)
    if computed == total_runs and not quick:
        record.write_text(json.dumps(now, indent=1) + "\n")
    lines += [
        "## Run",
        "",
        f"- wall time of this `{'tfm paper --quick' if quick else 'make paper'}`: **{wall / 60:.1f} min** "
        f"({wall:.0f} s) with `--jobs {jobs}`, "
        f"{total_runs} runs in {len(runs)} campaigns, {computed} of them computed by this invocation "
        f"({'a full run from empty result folders' if computed == total_runs else f'the rest resumed from {Path(results_dir).as_posix()}/'}); "
        f"the runs' own compute time adds up to {run_seconds:.0f} s (with each worker's first compilation of the "
        "kernels, 1-2 min after an install or a code change).",
        f"- machine: {m['nproc']} cores, {m['cpu']}, Python {m['python']}; load average "
        f"{start_machine['load'][0]:.1f} at the start and {m['load'][0]:.1f} at the end "
        "(a load above the core count means other work shared the machine and the time is pessimistic).",
    ]
    last = _read_json(record) if computed < total_runs else None
    if last:
        lines.append(
            f"- the last full run from empty result folders ({last['date']}, `--jobs {last['jobs']}`, "
            f"{last['runs']} runs): **{last['wall'] / 60:.1f} min** wall, the runs' own compute time "
            f"{last['run_seconds']:.0f} s, load average {last['load_start']:.1f} at the start and "
            f"{last['load_end']:.1f} at the end on {last['nproc']} cores.")
    lines += [
        f"- campaigns (results in `{Path(results_dir).as_posix()}/<name>/`; the same command again resumes and "
        "only analyses):",
        "",
        "| campaign | runs | computed now | wall time (s) | what" + (" (the full-size values; these quick runs "
                                                                    "doubled every spacing and step)" if quick else "")
        + " |",
        "|---|---|---|---|---|",
    ]
    for r in runs.values():
        lines.append(f"| [`{r.name}`]({_link(r.path, path)}) | {r.n_runs} | {r.computed} | {r.seconds:.0f} | "
                     f"{r.description} |")
    lines += ["", _flagged_text(runs)]
    lines += ["", "## The paper's claims beside tfm's values", "",
              "| where | claim | paper | tfm | agrees |", "|---|---|---|---|---|"]
    for c in res.claims:
        lines.append(f"| {c.section} | {c.claim} | {c.paper} | {c.tfm} | {c.agrees} |")
    lines += ["", "Exponent intervals are 95 % Student-t intervals of an ordinary least-squares fit in "
              "log-log space (`tfm.analysis`); with few points they are wide, and the stated physics "
              "tolerances in `tests/test_scaling*.py` are the regression targets. The agreement "
              "thresholds are named constants in `tfm/paper/claims.py`.", ""]
    numbers = dict(res.numbers, _fig5_table=res.tables.get("fig5"), _fig4_table=res.tables.get("fig4"))
    lines += discussion(numbers, limit_line)
    for key, title, table in SECTIONS:
        if key not in figures:
            continue
        if key == "fig3" and "fig3_case" in res.numbers:
            title += " at " + res.numbers["fig3_case"]
        lines += [f"## {title}", "", f"![{title}]({figures[key]})", ""]
        if table and table in res.tables:
            lines += [md_table(res.tables[table]), ""]
        if key in ("fig4", "fig5") and key + "_ratios" in res.tables:
            lines += [md_table(res.tables[key + "_ratios"]), ""]
        if key == "kernels":
            lines += ["Every run of the kernel study:", "", md_table(res.tables["kernels"]), ""]
    path.write_text("\n".join(lines) + "\n")
