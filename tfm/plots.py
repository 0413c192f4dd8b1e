"""Figures in the style of the paper: force against indentation, contact radius against force."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import theory  # noqa: E402

PHASE_COLOURS = {"load": "tab:blue", "unload": "tab:red"}


def plot_curve(curve, params=None, path=None, title=None, hertz=True):
    """Two panels: (a) force vs indentation, (b) contact radius vs force; load in blue,
    unload in red, with the Hertz curve overlaid for reference."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for phase, colour in PHASE_COLOURS.items():
        part = curve[curve["phase"] == phase]
        ax1.plot(part["indent"], part["force"], ".-", ms=2, lw=0.8, color=colour, label=phase)
        ax2.plot(part["force"], part["contact_radius"], ".-", ms=2, lw=0.8, color=colour, label=phase)
    if hertz and params is not None and params.shape in ("sphere", "paraboloid") and params.kernel == "boussinesq":
        delta = np.linspace(0, params.delta_max, 200)
        P = theory.hertz_force(delta, params.radius)
        ax1.plot(delta, P, "k--", lw=0.8, label="Hertz (paraboloid)")
        ax2.plot(P, theory.hertz_radius(delta, params.radius), "k--", lw=0.8, label="Hertz (paraboloid)")
    ax1.set_xlabel("indentation $\\delta = -d$")
    ax1.set_ylabel("force $P$ (compression > 0)")
    ax2.set_xlabel("force $P$ (compression > 0)")
    ax2.set_ylabel("contact radius $a$")
    for ax in (ax1, ax2):
        ax.axhline(0, color="0.7", lw=0.5)
        ax.legend(frameon=False, fontsize=8)
    if title is None and params is not None:
        title = (f"spacing={params.spacing:.4g}, F_th={params.threshold_force:.3g}, "
                 f"alpha={params.alpha:g}, R={params.radius:g}, {params.shape}, {params.kernel}")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


# ---- the paper's figures (tfm.paper) -------------------------------------------
SPACING_COLOURS = ("tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink")


def _save(fig, path):
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


def _spacing_label(spacing):
    inv = 1.0 / spacing
    return f"$\\Delta$ = 1/{inv:.0f}" if abs(inv - round(inv)) < 1e-6 else f"$\\Delta$ = {spacing:.3g}"


def plot_hertz_validation(curves, radius, path=None, title=None):
    """Paper Fig. 2: (a) indentation against force, (b) force against contact radius, on
    the loading branch, one colour per spacing, the Hertz solution dashed.

    ``curves`` maps spacing -> curve DataFrame."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    dmax = 0.0
    for (spacing, curve), colour in zip(sorted(curves.items(), reverse=True), SPACING_COLOURS):
        load = curve[curve["phase"] == "load"]
        dmax = max(dmax, float(load["indent"].max()))
        ax1.plot(load["force"], load["indent"], ".", ms=3, color=colour, label=_spacing_label(spacing))
        ax2.plot(load["contact_radius"], load["force"], ".", ms=3, color=colour, label=_spacing_label(spacing))
    delta = np.linspace(0, dmax, 300)
    P = theory.hertz_force(delta, radius)
    ax1.plot(P, delta, "k--", lw=1, label="Hertz")
    ax2.plot(theory.hertz_radius(delta, radius), P, "k--", lw=1, label="Hertz")
    ax1.set_xlabel("force $P$ (compression > 0)")
    ax1.set_ylabel("indentation $\\delta$")
    ax2.set_xlabel("contact radius $a$")
    ax2.set_ylabel("force $P$ (compression > 0)")
    ax1.set_title("(a) indentation vs force", fontsize=9)
    ax2.set_title("(b) force vs contact radius", fontsize=9)
    for ax in (ax1, ax2):
        ax.legend(frameon=False, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_load_unload(curve, radius, k_ic=None, path=None, title=None):
    """Paper Fig. 3: ``plot_curve``'s two panels (loading blue, unloading red), with Hertz
    dashed and, given the effective toughness ``k_ic``, the JKR curve dotted (its
    receding branch, a up to the preload radius)."""
    fig = plot_curve(curve, params=None, path=None, title=title, hertz=False)
    ax1, ax2 = fig.axes[:2]
    dmax = float(curve["indent"].max())
    delta = np.linspace(0, dmax, 300)
    P = theory.hertz_force(delta, radius)
    ax1.plot(delta, P, "k--", lw=0.8, label="Hertz")
    ax2.plot(P, theory.hertz_radius(delta, radius), "k--", lw=0.8, label="Hertz")
    if k_ic:
        a = np.linspace(1e-4, float(theory.hertz_radius(dmax, radius)), 400)
        d_j, P_j = theory.jkr_curve(k_ic, radius, a)
        ax1.plot(d_j, P_j, "k:", lw=1.2, label=f"JKR, $K$ = {k_ic:.3g}")
        ax2.plot(P_j, a, "k:", lw=1.2, label="JKR")
    for ax in (ax1, ax2):
        ax.legend(frameon=False, fontsize=8)
    return _save(fig, path)


def plot_refinement(curves, radius, k_ic=None, path=None, title=None, zoom=True, predicted_slope=None):
    """Paper Figs. 4 and 5: load-unload curves at several spacings, one colour per
    spacing (loading thin, unloading thick). (a) force against indentation, (b) contact
    radius against force, (c) F_max against spacing (log-log) with the predicted slope.
    ``k_ic`` (a number, or a dict spacing -> K_eff) overlays the JKR curve(s) dotted.
    With ``zoom`` the axes are cut to show the tensile part."""
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(14, 4.2))
    fmin, xmax, xmin = 0.0, 0.0, 0.0
    fmax_by = {}
    for (spacing, curve), colour in zip(sorted(curves.items(), reverse=True), SPACING_COLOURS):
        load = curve[curve["phase"] == "load"]
        unload = curve[curve["phase"] == "unload"]
        fmin = min(fmin, float(curve["force"].min()))
        fmax_by[spacing] = -float(curve["force"].min())
        xmin = min(xmin, float(unload["indent"].min()))
        lab = _spacing_label(spacing)
        ax1.plot(load["indent"], load["force"], "-", lw=0.6, color=colour, alpha=0.6)
        ax1.plot(unload["indent"], unload["force"], "-", lw=1.2, color=colour, label=lab + " (unload)")
        ax2.plot(load["force"], load["contact_radius"], "-", lw=0.6, color=colour, alpha=0.6)
        ax2.plot(unload["force"], unload["contact_radius"], "-", lw=1.2, color=colour, label=lab)
        dmax = float(curve["indent"].max())
    if zoom and fmin < 0:
        for curve in curves.values():
            unload = curve[curve["phase"] == "unload"]
            inside = unload[unload["force"] <= -4.0 * fmin]
            xmax = max(xmax, float(inside["indent"].max()) if len(inside) else dmax)
    if k_ic:
        ks = k_ic if isinstance(k_ic, dict) else {None: k_ic}
        for (spacing, k), colour in zip(sorted(ks.items(), key=lambda kv: -(kv[0] or 0)), SPACING_COLOURS):
            a = np.linspace(1e-4, float(theory.hertz_radius(dmax, radius)), 400)
            d_j, P_j = theory.jkr_curve(k, radius, a)
            c = "k" if spacing is None else colour
            ax1.plot(d_j, P_j, ":", lw=1.2, color=c)
            ax2.plot(P_j, a, ":", lw=1.2, color=c)
        ax1.plot([], [], "k:", label="JKR (dotted)")
    ax1.plot([], [], "-", lw=0.6, color="0.5", label="loading (thin)")
    ax1.set_xlabel("indentation $\\delta = -d$")
    ax1.set_ylabel("force $P$ (compression > 0)")
    ax2.set_xlabel("force $P$ (compression > 0)")
    ax2.set_ylabel("contact radius $a$")
    if zoom and fmin < 0:
        ax1.set_ylim(1.3 * fmin, -4.0 * fmin)
        ax1.set_xlim(xmin - 0.1 * (xmax - xmin), xmax)
        ax2.set_xlim(1.3 * fmin, -4.0 * fmin)
    for ax in (ax1, ax2):
        ax.axhline(0, color="0.7", lw=0.5)
        ax.legend(frameon=False, fontsize=7)
    ax2.ticklabel_format(axis="x", style="sci", scilimits=(-2, 2))
    ax1.set_title("(a) force vs indentation (tensile part)", fontsize=9)
    ax2.set_title("(b) contact radius vs force", fontsize=9)
    sp = np.array(sorted(fmax_by))
    fm = np.array([fmax_by[s] for s in sp])
    ax3.loglog(sp, fm, "o-", color="tab:blue", label="tfm $F_{max}$")
    if k_ic:
        ks = k_ic if isinstance(k_ic, dict) else {s: k_ic for s in sp}
        ax3.loglog(sp, [theory.jkr_pull_off(ks[s], radius) for s in sp], "k:", marker="x",
                   label="JKR, $K_{eff} = F_{th}/\\Delta^{1.5}$")
    if predicted_slope is not None and len(sp):
        mid = len(sp) // 2
        ax3.loglog(sp, fm[mid] * (sp / sp[mid]) ** predicted_slope, "--", color="tab:red", lw=0.8,
                   label=f"slope {predicted_slope:g} (4$\\alpha$ - 3)")
    lo, hi = float(fm.min()), float(fm.max())
    if hi / lo < 10:                      # show a near-constant series as near-constant
        ax3.set_ylim(lo / 3.0, hi * 3.0)
    ax3.set_xlabel("spacing $\\Delta$")
    ax3.set_ylabel("$F_{max}$")
    ax3.set_title("(c) pull-off force against spacing", fontsize=9)
    ax3.legend(frameon=False, fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_jkr_scaling(k_data, r_data, k_fit, r_fit, coef_fit, path=None, title=None):
    """Paper Fig. 6: (a) F_max against K_th^2 (R = 1), (b) F_max against R. Points,
    the fitted line F = c K^2 R, the paper's 7.6 and JKR/LEFM's 3 pi^2/4.

    ``k_data`` / ``r_data``: DataFrames with columns k_th, radius, f_max. ``k_fit`` and
    ``r_fit`` are tfm.analysis.PowerLawFit, ``coef_fit`` a LineFit of F on K^2 R."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    k2 = k_data["k_th"].to_numpy() ** 2
    ax1.plot(k2, k_data["f_max"], "o", color="tab:blue", label="tfm")
    kk = np.linspace(0, k2.max() * 1.05, 50)
    r0 = float(k_data["radius"].iloc[0])
    ax1.plot(kk, coef_fit.slope * kk * r0, "-", color="tab:blue", lw=1,
             label=f"fit: $F = {coef_fit.slope:.2f}\\,K^2R$")
    ax1.plot(kk, theory.PAPER_COEFFICIENT * kk * r0, "--", color="tab:red", lw=1, label="paper: 7.6")
    ax1.plot(kk, theory.JKR_COEFFICIENT * kk * r0, ":", color="k", lw=1.2, label="JKR/LEFM: $3\\pi^2/4$ = 7.40")
    ax1.set_xlabel("$K_{th}^2$")
    ax1.set_ylabel("$F_{max}$")
    ax1.set_title(f"(a) R = {r0:g}; exponent of $K_{{th}}$: {k_fit.text(3)}", fontsize=9)
    R = r_data["radius"].to_numpy()
    k0 = float(r_data["k_th"].iloc[0])
    ax2.plot(R, r_data["f_max"], "o", color="tab:blue", label="tfm")
    rr = np.linspace(0, R.max() * 1.05, 50)
    ax2.plot(rr, r_fit.predict(np.maximum(rr, 1e-12)), "-", color="tab:blue", lw=1,
             label=f"power-law fit, exponent {r_fit.exponent:.3f}")
    ax2.plot(rr, theory.PAPER_COEFFICIENT * k0 ** 2 * rr, "--", color="tab:red", lw=1, label="paper: 7.6 $K^2R$")
    ax2.plot(rr, theory.JKR_COEFFICIENT * k0 ** 2 * rr, ":", color="k", lw=1.2, label="JKR/LEFM: 7.40 $K^2R$")
    ax2.set_xlabel("radius $R$")
    ax2.set_ylabel("$F_{max}$")
    ax2.set_title(f"(b) $K_{{th}}$ = {k0:g}; exponent of R: {r_fit.text(3)}", fontsize=9)
    for ax in (ax1, ax2):
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.legend(frameon=False, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_kernel_study(summary, slopes, crossings, path=None, title=None):
    """Section 3.2: one panel per kernel with F_max against spacing (log-log, normalized
    by the coarsest spacing, one line per alpha), and a last panel with the spacing
    slope against alpha per kernel, the fitted line and its zero crossing alpha*."""
    kernels = sorted(summary["p_kernel"].unique())
    fig, axes = plt.subplots(1, len(kernels) + 1, figsize=(4.2 * (len(kernels) + 1), 4.2))
    markers = {"boussinesq": "o", "local": "s", "neighbors": "^"}
    colours = {"boussinesq": "tab:blue", "local": "tab:green", "neighbors": "tab:orange"}
    cmap = plt.get_cmap("viridis")
    for ax, kernel in zip(axes, kernels):
        part = summary[summary["p_kernel"] == kernel]
        alphas = sorted(part["p_alpha"].unique())
        for i, alpha in enumerate(alphas):
            g = part[part["p_alpha"] == alpha].sort_values("p_spacing")
            f0 = g["r_pull_off_force"].iloc[-1]
            ax.loglog(g["p_spacing"], g["r_pull_off_force"] / f0, "-", marker=markers.get(kernel, "o"), ms=4,
                      color=cmap(i / max(1, len(alphas) - 1)), label=f"$\\alpha$ = {alpha:g}")
        ax.axhline(1.0, color="0.6", lw=0.6)
        ax.set_xlabel("spacing $\\Delta$")
        ax.set_ylabel("$F_{max}$ / $F_{max}$(coarsest)")
        ax.set_title(f"{kernel}", fontsize=9)
        ax.legend(frameon=False, fontsize=7)
    ax2 = axes[-1]
    for k_i, (kernel, g) in enumerate(slopes.groupby("p_kernel")):
        c = colours.get(kernel)
        ax2.errorbar(g["p_alpha"], g["slope"], yerr=[g["slope"] - g["ci_low"], g["ci_high"] - g["slope"]],
                     fmt=markers.get(kernel, "o"), color=c, ms=5, capsize=2,
                     label=f"{kernel}: $\\alpha^*$ = {crossings[kernel].text(3)}" if kernel in crossings else kernel)
        zc = crossings.get(kernel)
        if zc is not None:
            aa = np.linspace(g["p_alpha"].min() - 0.05, g["p_alpha"].max() + 0.05, 20)
            ax2.plot(aa, zc.intercept + zc.gradient * aa, "-", color=c, lw=0.8)
            ax2.axvline(zc.alpha, color=c, lw=0.6, ls=":")
    ax2.axhline(0, color="0.6", lw=0.6)
    ax2.set_xlabel("$\\alpha$")
    ax2.set_ylabel("d ln $F_{max}$ / d ln $\\Delta$")
    ax2.set_title("spacing slope; zero crossing = convergent $\\alpha$", fontsize=9)
    ax2.legend(frameon=False, fontsize=7, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)
