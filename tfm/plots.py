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
