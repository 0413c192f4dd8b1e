"""Rough-sphere adhesion: the figure and table of results/rough/ from campaigns/rough_sphere.toml.

Reads results/rough_sphere/{summary,curves}.parquet (run the campaign first:
``make campaign NAME=rough_sphere``), runs the smooth reference sphere (the campaign's
base without roughness), and writes results/rough/rough_sphere.png and
results/rough/rough_sphere_table.md:

- pull-off force / smooth pull-off against the Fuller-Tabor adhesion parameter
  theta = E* sigma^(3/2) / (beta^(1/2) gamma) (Fuller & Tabor, Proc. R. Soc. A 345, 327
  (1975)), with sigma the rms height and beta the mean summit radius of the realized
  surface, beta = 3 sqrt(pi) / (8 sqrt(m4)) (Nayak 1971, high-bandwidth limit; m4 the
  profile's fourth spectral moment, 3/8 <(lap h)^2> for an isotropic surface);
  gamma = pi K_th^2 / 2 and E* = 1/pi in the paper's units (docs/physics.md);
- the hysteresis (energy dissipated in the load-unload cycle, tfm.analysis.hysteresis)
  against the rms height, with the smooth sphere's;
- mean and seed-to-seed standard deviation over the roughness seeds.

    python -m bench.rough_report
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

import tfm
from tfm.analysis import ensemble_stats, run_metrics
from tfm.campaign.spec import load_spec
from tfm.geometry import heights, make_layout
from tfm.params import Params
from tfm.surfaces import fourier_synthesis, grid_side, wavevectors
from tfm.theory import E_STAR, gamma_from_k

# the repository's folders, wherever it is run from (it failed outside the root with a
# traceback: "campaigns/rough_sphere.toml: no such campaign file")
ROOT = Path(__file__).resolve().parent.parent
CAMPAIGN = ROOT / "campaigns/rough_sphere.toml"
OUT = ROOT / "results/rough"
ROUGH_FIELDS = ("rms_height", "rms_slope", "hurst", "short_cutoff", "long_cutoff", "rolloff", "roughness_seed")


def summit_radius(p: Params) -> float:
    """Mean summit radius of the run's realized roughness (Nayak: 3 sqrt(pi)/(8 sqrt(m4)))."""
    n = grid_side(p)
    h = fourier_synthesis(n, p.spacing, p.hurst, rms_height=p.rms_height, rms_slope=p.rms_slope,
                          short_cutoff=p.short_cutoff, long_cutoff=p.long_cutoff, rolloff=p.rolloff,
                          seed=p.roughness_seed)
    q = wavevectors(n, p.spacing)
    lap2 = float((q ** 4 * np.abs(np.fft.fft2(h)) ** 2).sum()) / n ** 4
    return 3.0 * math.sqrt(math.pi) / (8.0 * math.sqrt(3.0 / 8.0 * lap2))


def smooth_reference(spec) -> tuple[Params, dict]:
    base = {k: v for k, v in spec.base.items() if k not in ROUGH_FIELDS}
    p = Params.from_dict(base)
    res = tfm.simulate(p)
    return p, {**run_metrics(res.curve), "flags": res.summary["warnings"]}


def main():
    spec = load_spec(CAMPAIGN)
    summary = pd.read_parquet(ROOT / "results/rough_sphere/summary.parquet")
    curves = pd.read_parquet(ROOT / "results/rough_sphere/curves.parquet")
    by_id = {r.run_id: r.params for r in spec.runs}
    p0, smooth = smooth_reference(spec)
    gamma = gamma_from_k(p0.k_th)
    summary["beta"] = [summit_radius(by_id[rid]) for rid in summary["run_id"]]
    summary["theta_ft"] = E_STAR * summary["p_rms_height"] ** 1.5 / (np.sqrt(summary["beta"]) * gamma)
    stats = ensemble_stats(summary, curves, by=["p_rms_height"])
    theta = summary.groupby("p_rms_height")["theta_ft"].mean()
    beta = summary.groupby("p_rms_height")["beta"].mean()
    stats["theta_ft"] = stats["p_rms_height"].map(theta)
    stats["beta"] = stats["p_rms_height"].map(beta)
    stats["pull_off_ratio_mean"] = stats["pull_off_force_mean"] / smooth["pull_off_force"]
    stats["pull_off_ratio_std"] = stats["pull_off_force_std"] / smooth["pull_off_force"]
    stats["hysteresis_ratio_mean"] = stats["hysteresis_mean"] / smooth["hysteresis"]
    stats["hysteresis_ratio_std"] = stats["hysteresis_std"] / smooth["hysteresis"]
    stats["area_ratio_mean"] = stats["area_at_max_load_mean"] / smooth["area_at_max_load"]
    OUT.mkdir(parents=True, exist_ok=True)
    flagged = int((summary["status"] != "ok").sum())
    lines = [f"Campaign `{spec.name}`: {len(summary)} runs ({flagged} flagged), "
             f"{summary['r_n_springs'].iloc[0]} springs each; total solve time "
             f"{summary['r_wall_time'].sum():.0f} s. Smooth reference: pull-off "
             f"{smooth['pull_off_force']:.5g}, hysteresis {smooth['hysteresis']:.4g}, "
             f"area at max load {smooth['area_at_max_load']:.4g} {('(' + smooth['flags'] + ')') if smooth['flags'] else ''}.",
             f"JKR radius a_c = {tfm.theory.jkr_critical_radius(p0.k_th, p0.radius):.3f}, gamma = {gamma:.4g}, "
             f"adhesive length (gamma^2 beta / E*^2)^(1/3) per row below.", "",
             "| rms height σ | summit radius β | θ_FT | σ / ℓ_a | pull-off / smooth (mean ± std, n) "
             "| hysteresis / smooth | area at max load / smooth |", "|---|---|---|---|---|---|---|"]
    for _, r in stats.iterrows():
        ell = (gamma ** 2 * r["beta"] / E_STAR ** 2) ** (1 / 3)
        lines.append(f"| {r['p_rms_height']:.3g} | {r['beta']:.3g} | {r['theta_ft']:.3g} | {r['p_rms_height'] / ell:.3g} "
                     f"| {r['pull_off_ratio_mean']:.3f} ± {r['pull_off_ratio_std']:.3f} ({int(r['n'])}) "
                     f"| {r['hysteresis_ratio_mean']:.3f} ± {r['hysteresis_ratio_std']:.3f} "
                     f"| {r['area_ratio_mean']:.3f} |")
    text = "\n".join(lines)
    (OUT / "rough_sphere_table.md").write_text(text + "\n")
    print(text)
    _figure(summary, curves, stats, smooth, OUT / "rough_sphere.png")


def _figure(summary, curves, stats, smooth, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    per_run = summary[["run_id", "p_rms_height", "theta_ft"]].copy()
    metrics = {rid: run_metrics(c) for rid, c in curves.groupby("run_id")}
    per_run["ratio"] = [metrics[r]["pull_off_force"] / smooth["pull_off_force"] for r in per_run["run_id"]]
    per_run["hyst"] = [metrics[r]["hysteresis"] / smooth["hysteresis"] for r in per_run["run_id"]]
    ax[0].semilogx(per_run["theta_ft"], per_run["ratio"], "o", mfc="none", color="0.6", label="each seed")
    ax[0].errorbar(stats["theta_ft"], stats["pull_off_ratio_mean"], yerr=stats["pull_off_ratio_std"], fmt="s-",
                   color="C0", capsize=3, label="mean ± std over seeds")
    ax[0].axhline(1.0, color="k", lw=0.8, ls=":")
    ax[0].set(xlabel="Fuller–Tabor parameter θ = E* σ^1.5 / (β^0.5 γ)", ylabel="pull-off / smooth pull-off",
              title="rough sphere, α = 0.75")
    # the flagged runs (the README says why: an rms slope above 1), marked where they are
    bad = summary["status"] != "ok"
    if bad.any():
        marked = per_run[bad.to_numpy()]
        ax[0].plot(marked["theta_ft"], marked["ratio"], "x", color="C3", ms=7, label="flagged run")
        ax[1].plot(marked["p_rms_height"], marked["hyst"], "x", color="C3", ms=7, label="flagged run")
        ax[1].legend(fontsize=8)
    ax[0].legend(fontsize=8)
    ax[1].semilogx(per_run["p_rms_height"], per_run["hyst"], "o", mfc="none", color="0.6")
    ax[1].errorbar(stats["p_rms_height"], stats["hysteresis_ratio_mean"], yerr=stats["hysteresis_ratio_std"],
                   fmt="s-", color="C1", capsize=3)
    ax[1].axhline(1.0, color="k", lw=0.8, ls=":")
    # the swept values as ticks: a log axis over less than a decade showed only 10^-2
    ax[1].set_xticks(stats["p_rms_height"], [f"{v:g}" for v in stats["p_rms_height"]])
    ax[1].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax[1].set(xlabel="rms height σ", ylabel="hysteresis / smooth hysteresis", title="energy dissipated per cycle")
    # one seed's curves at each rms height
    seed0 = summary[summary["p_roughness_seed"] == 0].sort_values("p_rms_height")
    for i, (_, r) in enumerate(seed0.iterrows()):
        c = curves[curves["run_id"] == r["run_id"]]
        ax[2].plot(c["indent"], c["force"], lw=0.8, color=plt.cm.viridis(i / max(len(seed0) - 1, 1)),
                   label=f"σ = {r['p_rms_height']:.3g}")
    ax[2].set(xlabel="indentation δ (from first touch)", ylabel="force P (compressive > 0)", title="seed 0")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)



def punch_table():
    """Contact fraction at maximum load and the A(P) slope of the rough punch campaign."""
    spec = load_spec(ROOT / "campaigns/rough_punch_area_load.toml")
    summary = pd.read_parquet(ROOT / "results/rough_punch_area_load/summary.parquet")
    curves = pd.read_parquet(ROOT / "results/rough_punch_area_load/curves.parquet")
    p = spec.runs[0].params
    nominal = math.pi * p.radius ** 2
    stats = ensemble_stats(summary, curves, by=["p_k_th"])
    # kappa = A E* h'_rms / P on the loading branch, below 10 % contact (the linear regime)
    kappas = {}
    for rid, c in curves.groupby("run_id"):
        load = c[(c["phase"] == "load") & (c["force"] > 0) & (c["contact_area"] < 0.1 * nominal)]
        kappas[rid] = float(np.median(load["contact_area"] * E_STAR * p.rms_slope / load["force"]))
    summary["kappa"] = summary["run_id"].map(kappas)
    kappa = summary.groupby("p_k_th")["kappa"].agg(["mean", "std"])
    lines = ["| k_th | contact fraction at max load (mean ± std over 3 seeds) | pull-off force | "
             "hysteresis | κ = A E* h'_rms / P below 10 % contact |", "|---|---|---|---|---|"]
    for _, r in stats.iterrows():
        k = kappa.loc[r["p_k_th"]]
        lines.append(f"| {r['p_k_th']:g} | {r['area_at_max_load_mean'] / nominal:.3f} ± "
                     f"{r['area_at_max_load_std'] / nominal:.3f} | {r['pull_off_force_mean']:.3g} ± "
                     f"{r['pull_off_force_std']:.2g} | {r['hysteresis_mean']:.3g} ± {r['hysteresis_std']:.2g} "
                     f"| {k['mean']:.2f} ± {k['std']:.2f} |")
    text = "\n".join(lines)
    (OUT / "rough_punch_table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
    if (ROOT / "results/rough_punch_area_load/summary.parquet").exists():
        punch_table()
