"""Figures in the style of the paper: force against indentation, contact radius against
force, the paper's figures (tfm.paper), and contact maps of field snapshots.

Every figure is 7 in wide (a two-column journal figure; each panel then prints at about
a column's width) with 8-pt text, panels lettered (a), (b), ...; PNGs at 200 dpi. The
figures are built on ``matplotlib.figure.Figure`` with the Agg canvas, without pyplot:
importing this module stays cheap and no global figure state is kept.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
from matplotlib import rc_context
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatter, MaxNLocator, ScalarFormatter

from . import theory
from .units import COLUMN_UNITS, force_scale, unit_suffixes

PHASE_COLOURS = {"load": "tab:blue", "unload": "tab:red"}
SPACING_COLOURS = ("tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink")
WIDTH = 7.0                      # inches: a two-column figure
DPI = 200
STYLE = {"font.size": 8, "axes.labelsize": 8, "axes.titlesize": 8, "legend.fontsize": 7,
         "xtick.labelsize": 7, "ytick.labelsize": 7, "lines.linewidth": 1.0, "legend.frameon": False,
         "axes.formatter.use_mathtext": True}


def axis_label(name: str, kind: str, p=None, note: str = "") -> str:
    """``name``, `` in m`` / `` in N`` for an SI run (``kind`` "length" or "force"), `` in
    L*`` / `` in F*`` for a run in paper units, then `` (note)``: the one spelling of units
    for every figure of a run. Without a run (the paper's figures), no unit."""
    i = ("length", "force").index(kind)
    unit = (unit_suffixes(p)[i] or (" $L^*$", " $F^*$")[i]) if p is not None else ""
    return name + (f" in{unit}" if unit else "") + (f" ({note})" if note else "")


def force_label(p=None) -> str:
    return axis_label("force $P$", "force", p, "compression > 0")


def indent_label(p=None) -> str:
    return axis_label("indentation $\\delta = -d$", "length", p)


FORCE_LABEL = force_label()
INDENT_LABEL = indent_label()


# ---- shared helpers -----------------------------------------------------------
def figure(ncols=1, nrows=1, height=2.8, width=WIDTH, reuse=None):
    """A new figure, or ``reuse`` (an earlier one of the same size) cleared: its renderer
    then keeps the text measurements and parsed math text of what it drew before."""
    if reuse is not None and tuple(reuse.get_size_inches()) == (width, height):
        fig = reuse
        fig.clear()
    else:
        fig = Figure(figsize=(width, height), layout="constrained")
        FigureCanvasAgg(fig)        # its own canvas: savefig keeps its renderer
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    return fig, list(axes)


def letter(axes, start=0):
    """Panel letters (a), (b), ... at the top left of each panel."""
    for i, ax in enumerate(axes):
        ax.text(-0.02, 1.02, f"({chr(ord('a') + start + i)})", transform=ax.transAxes, ha="right",
                va="bottom", fontweight="bold", fontsize=9)


def tidy_ticks(*axes, nbins=5):
    """At most ``nbins`` ticks per axis and a common power of ten as offset: no overlaps."""
    for ax in axes:
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() != "linear":
                continue
            axis.set_major_locator(MaxNLocator(nbins=nbins))
            fmt = ScalarFormatter(useMathText=True)
            fmt.set_powerlimits((-2, 3))
            axis.set_major_formatter(fmt)


class _PlainLogFormatter(LogFormatter):
    """Log-axis labels as plain numbers (0.3, 2, 4) rather than 3×10⁻¹: the ratio axes
    span about one decade, where Matplotlib labels minor ticks in scientific notation."""

    def _num_to_string(self, x, vmin, vmax):
        return f"{x:g}"


def plain_log_ticks(axis):
    """Plain-number labels on a log ``axis`` (major and the minor ticks Matplotlib labels)."""
    axis.set_major_formatter(_PlainLogFormatter(labelOnlyBase=False))
    axis.set_minor_formatter(_PlainLogFormatter(labelOnlyBase=False, minor_thresholds=(2, 0.5)))


def fraction_ticks(ax, spacings):
    """Spacing ticks of a log axis as 1/64, 1/128 (and no minor ticks on that axis)."""
    from matplotlib.ticker import NullLocator

    ax.set_xticks(spacings, [spacing_text(s) for s in spacings])
    ax.xaxis.set_minor_locator(NullLocator())


def fold_offsets(fig):
    """Move a linear axis' common factor (×10⁻²) into its label: below the right end of
    an x axis a long label ran into it, and above a y axis it ran into the panel's title.
    A label with a note in parentheses gets the factor beside its unit and the note on a
    second line."""
    for ax in fig.axes:
        for axis, get_label, set_label, lim in ((ax.xaxis, ax.get_xlabel, ax.set_xlabel, ax.get_xlim),
                                                (ax.yaxis, ax.get_ylabel, ax.set_ylabel, ax.get_ylim)):
            fmt = axis.get_major_formatter()
            if axis.get_scale() != "linear" or not isinstance(fmt, ScalarFormatter) or not get_label():
                continue
            lo, hi = lim()
            fmt.set_locs([t for t in axis.get_majorticklocs() if min(lo, hi) <= t <= max(lo, hi)])
            offset = fmt.get_offset()
            if offset and "(" + offset not in get_label():
                label = get_label()
                if label.endswith(")") and " (" in label:
                    # the factor beside the unit, the note on a second line: one line ran
                    # past the top of the axes into the panel's letter (y), or past the
                    # figure's edge under a narrow panel (x)
                    name, note = label.rsplit(" (", 1)
                    set_label(f"{name} ({offset})\n({note}")
                else:
                    set_label(f"{label} ({offset})")
                axis.get_offset_text().set_visible(False)


def number(x, digits=3) -> str:
    """A number for a caption: 2×10⁻⁵ rather than 2e-05, 0.135 rather than 0.13500.
    Rounded first, then written: 9.9996e-6 is 10⁻⁵, not 10×10⁻⁶, and 9999.6 is 10⁴, not
    1e+04; -0.0 is 0; negative numbers with a minus sign, not a hyphen, in either form."""
    if x == 0:
        return "0"
    if not math.isfinite(x):
        return f"{x:g}"
    mant, exp = f"{x:.{digits - 1}e}".split("e")
    exp = int(exp)
    if -3 <= exp < 4:
        text = f"{float(f'{mant}e{exp}'):.{max(digits - 1 - exp, 0)}f}"
        text = text.rstrip("0").rstrip(".") if "." in text else text
        return text.replace("-", "\u2212")      # the minus sign, as mathtext writes the others
    mant = mant.rstrip("0").rstrip(".") if "." in mant else mant
    if mant in ("1", "-1"):
        return f"${mant[:-1]}10^{{{exp}}}$"
    return f"${mant}\\times10^{{{exp}}}$"


def spacing_text(spacing) -> str:
    """1/128 rather than 0.007812; a power of ten as one (an SI spacing of 1e-5 m was
    1/100000)."""
    inv = 1.0 / spacing
    whole = abs(inv - round(inv)) < 1e-6 * inv
    if whole and round(inv) >= 10 and str(round(inv)).rstrip("0") == "1":
        return number(spacing)
    return f"1/{inv:.0f}" if whole else number(spacing)


def _spacing_label(spacing):
    return f"$\\Delta$ = {spacing_text(spacing)}"


def run_caption(p) -> str:
    """The parameters that matter for a run, caption style (alpha only where it acts)."""
    si = p.units == "si"
    m, N = unit_suffixes(p)
    if p.shape == "height_map":
        body = "height map " + Path(p.height_map).name.replace("$", "\\$")
    else:
        body = {"sphere": "sphere", "paraboloid": "paraboloid", "flat_punch": "flat punch"}[p.shape]
        body += f" $R$ = {p.radius:g}{m}"
    if p.f_th is not None:
        thr = f"$F_{{th}}$ = {number(p.f_th)}{N}"
    elif si:                  # K_th follows from the work of adhesion and c (tfm.units)
        from .units import resolve_coefficient

        c = p.k_th_coefficient
        name = f" ({c})" if isinstance(c, str) else ""
        thr = (f"$F_{{th}} = K_{{th}}A^{{3/4}}$ from $\\gamma$ = {number(p.work_of_adhesion)} J/m$^2$, "
               f"$c$ = {number(resolve_coefficient(c), 4)}{name}")
    else:
        thr = f"$F_{{th}} = K_{{th}}A^{{\\alpha}}$, $K_{{th}}$ = {number(p.k_th)}, $\\alpha$ = {p.alpha:g}"
    parts = [body, f"$\\Delta$ = {spacing_text(p.spacing)}{m}", thr]
    if p.rms_height > 0 or p.rms_slope > 0:
        rms = f"rms height {number(p.rms_height)}{m}" if p.rms_height > 0 else f"rms slope {number(p.rms_slope)}"
        parts.append(f"rough ($H$ = {p.hurst:g}, {rms}, seed {p.roughness_seed})")
    if p.threshold_disorder != "none":
        parts.append(f"{p.threshold_disorder} $F_{{th}}$ disorder {p.disorder_width:g} (seed {p.disorder_seed})")
    if si:
        parts.append(f"$E$ = {number(p.youngs_modulus)} Pa, $\\nu$ = {p.poisson_ratio:g}")
    if p.control == "force":
        parts.append(f"force control to $P_{{max}}$ = {number(p.peak_load)}{N}")
    else:
        parts.append(f"$\\delta_{{max}}$ = {number(p.delta_max)}{m}, step {number(p.step)}{m}")
    if p.kernel != "boussinesq":
        parts.append(f"{p.kernel} kernel")
    if p.layout == "jittered":           # the positions: said even at their defaults
        parts.append(f"jittered layout (jitter {p.jitter:g}, seed {p.seed})")
    elif p.layout != "square":
        parts.append(f"{p.layout} layout")
    if p.operator != "fft":
        parts.append(f"{p.operator} operator" + (f" ($\\theta$ = {p.theta:g})" if p.operator == "tree" else ""))
    dims = COLUMN_UNITS["paper"]["parameters"]      # which settings are lengths or forces
    unit = {"length": m, "force": N}
    parts += [f"{name} = {number(v) if isinstance(v, float) else v}{unit.get(dims.get(name), '')}"
              for name, v in _other_settings(p)]
    return ", ".join(parts)


# settings that change the numbers and are named above only when they are not the default
# (a self term of 3 and the single snap rule drew the default run's caption, with a
# pull-off 26 % lower)
CAPTION_SETTINGS = ("self_term", "snap_rule", "c_w", "neighbor_rings", "extent", "extent_margin",
                    "short_cutoff", "long_cutoff", "rolloff", "load_step", "tol")


def _other_settings(p):
    from .params import _DEFAULTS, APPLIES

    for name in CAPTION_SETTINGS:
        value = getattr(p, name)
        rule = APPLIES.get(name)
        if value == _DEFAULTS[name] or value is None or (rule is not None and not rule.applies(p)):
            continue
        yield name, value


# Visible characters of 8-pt caption text per inch of figure width (DejaVu Sans averages
# about 4.4 pt a character; 15 leaves a margin for wide glyphs and math italics).
CAPTION_CHARS_PER_INCH = 15


def _visible_length(text: str) -> int:
    """Characters a caption shows: a math-text command counts as one, markup as none."""
    return len(re.sub(r"[${}^_]", "", re.sub(r"\\[a-zA-Z]+", "x", text)))


def wrap_caption(text: str, width: float) -> str:
    """The caption broken at its ", " separators into lines that fit ``width`` inches
    (a long SI caption ran off both edges of the figure). Never inside math text."""
    parts = text.split(", ")
    if any(part.count("$") % 2 for part in parts):
        return text
    limit = CAPTION_CHARS_PER_INCH * width
    lines, line = [], ""
    for part in parts:
        joined = f"{line}, {part}" if line else part
        if line and _visible_length(joined) > limit:
            lines.append(line + ",")
            line = part
        else:
            line = joined
    return "\n".join(lines + [line])


def reference_label(p) -> str | None:
    """The analytical reference drawn for a run, named for what it is."""
    if p is None or p.kernel != "boussinesq" or p.shape == "height_map":
        return None                    # a measured topography has no closed-form curve
    smooth = ", smooth" if p.rms_height > 0 or p.rms_slope > 0 else ""
    if p.shape == "paraboloid":
        return f"Hertz{' (smooth)' if smooth else ''}"
    if p.shape == "sphere":
        return f"Hertz (paraboloid approx.{smooth})"       # short: a long name crossed its own line
    # short: the legend sits in the corner the line starts from, and a long name crossed it
    return f"{'smooth punch' if smooth else 'Boussinesq flat punch'}, $P = 2E^*R\\delta$"


def _save(fig, path):
    """Save through a temporary name beside ``path``: an interrupted or failed save leaves
    an earlier figure whole (tfm show wrote in place)."""
    from .results import through_temporary

    fold_offsets(fig)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with through_temporary(path, keep_suffix=True) as tmp:
            fig.savefig(tmp, dpi=DPI)
    return fig


def styled(func):
    """Draw with the module's style without changing the caller's rcParams."""
    def wrapper(*args, **kwargs):
        with rc_context(STYLE):
            return func(*args, **kwargs)
    wrapper.__name__, wrapper.__doc__ = func.__name__, func.__doc__
    return wrapper


# the columns a curve figure draws
CURVE_PLOT_COLUMNS = ("phase", "indent", "force", "contact_radius", "n_contact")


def curve_arrays(curve) -> dict[str, np.ndarray]:
    """The columns a curve figure draws, as NumPy arrays, from a DataFrame or from any
    mapping of columns: the figure's worker (tfm.plot_worker) draws from the curve's own
    columns without importing pandas, which took 0.2 s of its start."""
    return {c: np.asarray(curve[c]) for c in CURVE_PLOT_COLUMNS}


def _rows(cols, which):
    return {c: v[which] for c, v in cols.items()}


def split_snap_off(part):
    """The rows in contact, and the final row after the last snap (None if there is none),
    as ``curve_arrays``: a jump, to be drawn as one, not as a line through intermediate
    states. A contact that ends without tension (no adhesion) simply closes: no snap-off
    is drawn."""
    part = curve_arrays(part)
    if (part["force"].size > 1 and int(part["n_contact"][-1]) == 0
            and float(part["force"][-2]) < 0.0):
        return _rows(part, slice(None, -1)), _rows(part, slice(-2, None))
    return part, None


JUMP_POINTS = 200


def draw_jump(ax, x, y, colour, label=None):
    """A jump from (x[0], y[0]) to (x[1], y[1]): dotted arrow, open circle at the end."""
    ax.annotate("", xy=(x[1], y[1]), xytext=(x[0], y[0]),
                arrowprops=dict(arrowstyle="->", color=colour, ls=":", lw=1.0, shrinkA=0, shrinkB=2))
    # the same path as an unseen patch of many points: a legend placed "best" avoids the
    # vertices of lines and patches but not annotation arrows, and the flat punch's legend sat
    # on its jump (the curves' own lines have a vertex per step). A patch, not a line: the
    # axes' lines stay the drawn curves.
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    path = MplPath(np.column_stack([np.linspace(x[0], x[1], JUMP_POINTS), np.linspace(y[0], y[1], JUMP_POINTS)]))
    ax.add_patch(PathPatch(path, fill=False, alpha=0.0, lw=0.0))
    ax.plot([x[1]], [y[1]], "o", mfc="white", mec=colour, ms=3.5, label=label)


def draw_branches(ax1, ax2, curve, colours=PHASE_COLOURS, lw=1.0, labels=True):
    """Loading and unloading branches on (a) P(delta) and (b) a(P); the final snap-off as a jump."""
    cols = curve_arrays(curve)
    for phase, colour in colours.items():
        part = _rows(cols, cols["phase"] == phase)
        if not part["phase"].size:
            continue
        body, jump = split_snap_off(part) if phase == "unload" else (part, None)
        lab = phase if labels else None
        ax1.plot(body["indent"], body["force"], "-", lw=lw, color=colour, label=lab)
        ax2.plot(body["force"], body["contact_radius"], "-", lw=lw, color=colour, label=lab)
        if jump is not None:
            jl = "snap-off (jump)" if labels else None
            draw_jump(ax1, jump["indent"], jump["force"], colour, jl)
            draw_jump(ax2, jump["force"], jump["contact_radius"], colour, None)


def draw_reference(ax1, ax2, p, dmax, pmax=np.inf):
    """The analytical curve of the run's shape: P(delta) up to ``dmax`` on (a), a(P) up to
    ``pmax`` (the run's largest force) on (b)."""
    label = reference_label(p)
    if label is None:
        return
    delta = np.linspace(0, dmax, 200)
    # theory is in paper units; SI: L* = 1 m keeps the lengths
    P = theory.preload_force(p.shape, delta, p.radius) * force_scale(p)
    a = np.full_like(delta, p.radius) if p.shape == "flat_punch" else theory.hertz_radius(delta, p.radius)
    ax1.plot(delta, P, "k--", lw=0.8, label=label)
    # (b) compares a at the same force, over the run's forces: a rough punch's reference
    # reached 4x its largest force and squeezed its curve into the left quarter
    upto = P <= max(pmax, 0.0)
    upto[:2] = True
    ax2.plot(P[upto], a[upto], "k--", lw=0.8, label=label if p.shape != "flat_punch" else None)
    if p.shape == "flat_punch":          # (b) has no legend of its own: name the line there
        ax2.annotate("$a = R$", (P[upto][-1], p.radius), xytext=(0, -4), textcoords="offset points",
                     ha="right", va="top", fontsize=7)


# ---- one run ------------------------------------------------------------------
@styled
def plot_curve(curve, params=None, path=None, title=None, hertz=True, reuse=None):
    """Two panels: (a) force against indentation, (b) contact radius against force;
    loading blue, unloading red, the final snap-off as a jump, with the analytical
    reference for the run's shape (Hertz, or Boussinesq's flat punch) dashed. ``curve``: a
    DataFrame or a mapping of columns (``curve_arrays``)."""
    curve = curve_arrays(curve)
    fig, (ax1, ax2) = figure(2, reuse=reuse)
    draw_branches(ax1, ax2, curve)
    if hertz and params is not None:
        draw_reference(ax1, ax2, params, float(curve["indent"].max()), float(np.max(curve["force"])))
    _curve_axes(ax1, ax2, params)
    if title is None and params is not None:
        title = run_caption(params)
    if unload_incomplete(curve):
        title = f"{title}\n{INCOMPLETE}" if title else INCOMPLETE
    if title:
        fig.suptitle(wrap_caption(title, fig.get_figwidth()), fontsize=8)
    return _save(fig, path)


def write_curve_figure(curve, params, path, reuse=None) -> Path:
    """``plot_curve`` saved at ``path`` (through a temporary name, as every figure)."""
    plot_curve(curve, params, path, reuse=reuse)
    return Path(path)


def _curve_axes(ax1, ax2, p=None):
    ax1.set_xlabel(indent_label(p))
    ax1.set_ylabel(force_label(p))
    ax2.set_xlabel(force_label(p))
    # a rough contact is patches: its radius is that of a disc of the same area
    rough = p is not None and (p.rms_height > 0 or p.rms_slope > 0 or p.shape == "height_map")
    ax2.set_ylabel(axis_label("contact radius $a = \\sqrt{A/\\pi}$" if rough else "contact radius $a$",
                              "length", p))
    for ax in (ax1, ax2):
        ax.axhline(0, color="0.7", lw=0.5)
    # one legend: (b) draws the same lines, and a second box found no free corner in a(P)
    # (it covered the origin, where the curves start)
    ax1.legend(loc="best")
    tidy_ticks(ax1, ax2)
    letter((ax1, ax2))


# ---- contact maps (tfm show, tfm animate) -------------------------------------------
CONTACT_CMAP = "RdBu_r"          # diverging: tension (F > 0) red, compression blue


def force_limits(f_th_max, fields_force_min):
    """Colour limits: from the most compressive force shown up to the largest threshold
    F_th (a spring in contact never carries more tension), zero at the centre of the map.
    Without adhesion (F_th = 0) the upper limit is 0: there is no tension half (and both
    are 0 when no spring carries any force)."""
    hi = max(float(f_th_max), 0.0)
    return min(float(fields_force_min), -hi), hi


def spring_cells(x, y, params) -> list[np.ndarray]:
    """Each spring's cell, corners (k, 2) in data units: on the hexagonal lattice its
    Voronoi hexagon (pointy-topped, as the rows run along x; circumradius spacing/sqrt 3);
    on the jittered layout its Voronoi cell, the part of the plane nearer to it than to any
    other spring (so the contact line, halfway between neighbours, runs along cell edges),
    or where that cell is open or reaches past a spacing (the layout's rim) a square of
    side spacing."""
    spacing = float(params.get("spacing"))
    points = np.column_stack([x, y])
    if params.get("layout") == "hexagonal":
        angles = np.pi / 2 + np.arange(6) * np.pi / 3
        corners = spacing / np.sqrt(3.0) * np.column_stack([np.cos(angles), np.sin(angles)])
        return list(points[:, None, :] + corners[None, :, :])
    square = 0.5 * spacing * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    from scipy.spatial import Voronoi

    vor = Voronoi(points)
    cells = []
    for i, point in enumerate(points):
        region = vor.regions[vor.point_region[i]]
        corners = vor.vertices[region] if region and -1 not in region else None
        if corners is None or np.abs(corners - point).max() > spacing:
            corners = point + square
        cells.append(corners)
    return cells


class ContactMap:
    """The force per spring on a diverging map (tension red, compression blue; the colour
    bar ends at the threshold F_th, marked, or at the largest one when thresholds vary;
    compression only without adhesion), springs released by a snap in grey, and the
    contact line (boundary of the contact set) in black. ``params``, the run's record,
    gives the units. ``update(snap)`` redraws only what changes, for animations."""

    def __init__(self, ax, fields, snap, vlim=None, colorbar=True, params=None):
        import matplotlib as mpl

        self.ax, self.fields = ax, fields
        self.f_th = float(np.nanmax(fields.f_th))
        self.f_th_varies = float(np.nanmin(fields.f_th)) < self.f_th      # disorder, jittered areas
        if vlim is None:
            con = np.asarray(snap["state"]) == 1
            vlim = force_limits(self.f_th, np.asarray(snap["F"])[con].min() if con.any() else 0.0)
        lo, hi = vlim
        cmap = mpl.colormaps[CONTACT_CMAP]
        if hi > 0:
            self.norm = mpl.colors.TwoSlopeNorm(vcenter=0.0, vmin=lo, vmax=hi)
        else:        # no adhesion: the compressive half of the same colours, white at F = 0
            self.norm = mpl.colors.Normalize(vmin=lo if lo < 0 else -1.0, vmax=0.0)   # -1: no force at all
            cmap = mpl.colors.ListedColormap(cmap(np.linspace(0.0, 0.5, 128)))
        self.contour = None
        self._triangulation = None
        shown, released = self._layers(snap)
        if fields.grid:
            half = 0.5 * (fields.x[1] - fields.x[0])
            self.extent = [fields.x[0] - half, fields.x[-1] + half, fields.y[0] - half, fields.y[-1] + half]
            # arrays are [x, y]: transposed, x runs left to right and y upwards
            self.image = ax.imshow(shown.T, origin="lower", extent=self.extent, cmap=cmap,
                                   norm=self.norm, interpolation="nearest")
            self.grey = ax.imshow(released.T, origin="lower", extent=self.extent,
                                  cmap=mpl.colors.ListedColormap(["0.75"]), interpolation="nearest")
        else:
            from matplotlib.collections import PolyCollection

            x, y = fields.x, fields.y
            cells = spring_cells(x, y, fields.params)
            # cells in data units: markers sized in points for a guessed panel width came
            # out about twice a spring across and drew the contact larger than it was
            self.grey = PolyCollection(cells, facecolors="0.75", linewidths=0)
            self.image = PolyCollection(cells, array=shown, cmap=cmap, norm=self.norm, linewidths=0)
            self.grey.set_alpha(released)
            ax.add_collection(self.grey)
            ax.add_collection(self.image)
            corners = np.concatenate(cells)
            lo_xy, hi_xy = corners.min(axis=0), corners.max(axis=0)
            ax.set_xlim(lo_xy[0], hi_xy[0])
            ax.set_ylim(lo_xy[1], hi_xy[1])
        self._line(snap)
        ax.set_aspect("equal")
        # the grey and the black line are not on the colour bar: say what they are
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        ax.legend(handles=[Patch(facecolor="0.75", label="released (snapped)"),
                           Line2D([], [], color="k", lw=0.8, label="contact line")],
                  loc="upper left", fontsize="x-small", framealpha=0.85, handlelength=1.2)
        ax.set_xlabel(axis_label("$x$", "length", params))
        ax.set_ylabel(axis_label("$y$", "length", params))
        if colorbar:
            cb = ax.figure.colorbar(self.image, ax=ax, shrink=0.9, pad=0.02)
            cb.set_label(axis_label("spring force $F$", "force", params, "tension > 0"))
            ticks = [lo, 0.5 * lo, 0.0] if lo < 0 else [0.0]
            labels = [number(t, 2) for t in ticks]
            if hi > 0:
                name = "max $F_{th}$" if self.f_th_varies else "$F_{th}$"
                ticks += [0.5 * hi, hi]
                # the threshold's name at its tick, its value above the bar: a long tick
                # label pushed the bar's label far from the bar
                labels += [number(0.5 * hi, 2), name]
                cb.ax.set_title(f"{name} = {number(hi, 2)}{unit_suffixes(params)[1]}", fontsize="small", loc="left")
                cb.ax.axhline(hi, color="k", lw=1.5)
            cb.set_ticks(ticks, labels=labels)

    def _layers(self, snap):
        F = np.asarray(snap["F"], dtype=float)
        state = np.asarray(snap["state"])
        shown = np.where(state == 1, F, np.nan)
        released = (state == 2).astype(float) if not self.fields.grid else np.where(state == 2, 1.0, np.nan)
        return shown, released

    def _line(self, snap):
        """The 0.5 level of the contact indicator interpolated linearly between springs: on
        the lattice for the square grid, on the Delaunay triangulation of the springs for
        other layouts; either way it crosses every contact-to-free neighbour pair halfway."""
        if self.contour is not None:
            self.contour.remove()
            self.contour = None
        con = np.asarray(snap["state"]) == 1
        if not con.any() or con.all():
            return
        style = dict(levels=[0.5], colors="k", linewidths=0.8)
        if self.fields.grid:
            self.contour = self.ax.contour(self.fields.x, self.fields.y, con.astype(float).T, **style)
        else:
            if self._triangulation is None:
                from matplotlib.tri import Triangulation

                self._triangulation = Triangulation(self.fields.x, self.fields.y)
            self.contour = self.ax.tricontour(self._triangulation, con.astype(float), **style)

    def artists(self):
        """What changes from one snapshot to the next."""
        return [a for a in (self.image, self.grey, self.contour) if a is not None]

    def update(self, snap):
        shown, released = self._layers(snap)
        if self.fields.grid:
            self.image.set_data(shown.T)
            self.grey.set_data(released.T)
        else:
            self.image.set_array(shown)
            self.grey.set_alpha(released)
        self._line(snap)


EVENT_TEXT = {"pull_off": "pull-off", "max_load": "maximum load", "first_snap": "first snap",
              "last_contact": "last step in contact"}


def unload_incomplete(curve) -> bool:
    """The curve ends with springs in contact after unloading began: ``max_unload_steps``
    stopped it, and its "pull-off" is only the largest tension so far."""
    if curve is None:
        return False
    cols = curve_arrays(curve)
    if not cols["phase"].size:
        return False
    return str(cols["phase"][-1]) == "unload" and int(cols["n_contact"][-1]) > 0


INCOMPLETE = "unloading stopped with springs in contact (max_unload_steps): the pull-off may lie further"


def snapshot_title(snap, params=None, incomplete: bool = False) -> str:
    """``incomplete``: the run's unloading was capped (``unload_incomplete``)."""
    text = dict(EVENT_TEXT, pull_off="largest tension so far") if incomplete else EVENT_TEXT
    events = [text.get(e, "") for e in snap["event"].split(",") if e in text]
    ev = f" ({', '.join(events)})" if events else ""
    m, N = unit_suffixes(params)
    return (f"step {snap['step']}{ev}: $\\delta$ = {number(-snap['d'])}{m}, $P$ = {number(snap['force'])}{N}, "
            f"{snap['n_contact']} springs in contact")


def draw_curve_marker_panel(ax, curve, params=None):
    """P(delta) with both branches, for a panel beside a contact map; returns the marker."""
    draw_branches(ax, _NullAxes(), curve)
    (marker,) = ax.plot([], [], "o", color="k", ms=5, label="snapshot")
    ax.set_xlabel(indent_label(params))
    ax.set_ylabel(force_label(params))
    ax.axhline(0, color="0.7", lw=0.5)
    ax.legend(loc="best")
    tidy_ticks(ax)
    return marker


def map_figure(params, with_curve=True):
    ncols = 2 if with_curve else 1
    fig, axes = figure(ncols, height=3.3, width=WIDTH if with_curve else 4.0)
    fig.get_layout_engine().set(wspace=0.12)
    letter(axes)
    return fig, axes


@styled
def plot_contact_map(fields, snap, curve=None, params=None, path=None):
    """(a) the contact map of one snapshot; (b), given the curve, P(delta) with the
    snapshot marked."""
    fig, axes = map_figure(params, curve is not None)
    ContactMap(axes[0], fields, snap, params=params)
    tidy_ticks(axes[0])
    if curve is not None:
        marker = draw_curve_marker_panel(axes[1], curve, params)
        marker.set_data([-snap["d"]], [snap["force"]])
    head = wrap_caption(run_caption(params), fig.get_figwidth()) + "\n" if params is not None else ""
    fig.suptitle(head + snapshot_title(snap, params, unload_incomplete(curve)), fontsize=8)
    return _save(fig, path)


class _NullAxes:
    """Stands in for a panel that is not drawn."""

    def plot(self, *a, **k):
        return []

    def annotate(self, *a, **k):
        return None

    def add_patch(self, *a, **k):
        return None


# ---- the paper's figures (tfm.paper) -------------------------------------------
@styled
def plot_hertz_validation(curves, radius, path=None, title=None):
    """Paper Fig. 2: (a) indentation against force, (b) force against contact radius, on
    the loading branch, one colour per spacing, the Hertz solution dashed.

    ``curves`` maps spacing -> curve DataFrame."""
    fig, (ax1, ax2) = figure(2)
    dmax = 0.0
    for (spacing, curve), colour in zip(sorted(curves.items(), reverse=True), SPACING_COLOURS):
        load = curve[curve["phase"] == "load"]
        dmax = max(dmax, float(load["indent"].max()))
        ax1.plot(load["force"], load["indent"], ".", ms=2.5, color=colour, label=_spacing_label(spacing))
        ax2.plot(load["contact_radius"], load["force"], ".", ms=2.5, color=colour, label=_spacing_label(spacing))
    delta = np.linspace(0, dmax, 300)
    P = theory.hertz_force(delta, radius)
    ax1.plot(P, delta, "k--", lw=1, label="Hertz")
    ax2.plot(theory.hertz_radius(delta, radius), P, "k--", lw=1, label="Hertz")
    ax1.set_xlabel(FORCE_LABEL)
    ax1.set_ylabel("indentation $\\delta$")
    ax2.set_xlabel("contact radius $a$")
    ax2.set_ylabel(FORCE_LABEL)
    for ax in (ax1, ax2):
        ax.legend()
    tidy_ticks(ax1, ax2)
    letter((ax1, ax2))
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


@styled
def plot_load_unload(curve, radius, k_ic=None, path=None, title=None):
    """Paper Fig. 3: ``plot_curve``'s two panels (loading blue, unloading red, the final
    snap-off as a jump), Hertz dashed and, given the effective toughness ``k_ic``, the JKR
    curve dotted (its receding branch, a up to the preload radius). The body is a paraboloid."""
    fig, (ax1, ax2) = figure(2)
    draw_branches(ax1, ax2, curve)
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
    _curve_axes(ax1, ax2)
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


@styled
def plot_refinement(curves, radius, k_ic=None, path=None, title=None, zoom=True, predicted_slope=None):
    """Paper Figs. 4 and 5: load-unload curves at several spacings, one colour per
    spacing (loading thin, unloading thick). (a) force against indentation, (b) contact
    radius against force, (c) F_max against spacing (log-log) with the predicted slope.
    ``k_ic`` (a number, or a dict spacing -> K_eff) overlays the JKR curve(s) dotted.
    With ``zoom`` the axes are cut to show the tensile part."""
    fig, (ax1, ax2, ax3) = figure(3, height=2.6)
    fmin, xmax, xmin = 0.0, 0.0, 0.0
    fmax_by = {}
    dmax = 0.0
    for (spacing, curve), colour in zip(sorted(curves.items(), reverse=True), SPACING_COLOURS):
        load = curve[curve["phase"] == "load"]
        unload = curve[curve["phase"] == "unload"]
        fmin = min(fmin, float(curve["force"].min()))
        fmax_by[spacing] = -float(curve["force"].min())
        xmin = min(xmin, float(unload["indent"].min()))
        ax1.plot(load["indent"], load["force"], "-", lw=0.5, color=colour, alpha=0.6)
        ax2.plot(load["force"], load["contact_radius"], "-", lw=0.5, color=colour, alpha=0.6)
        draw_branches(ax1, ax2, unload, colours={"unload": colour}, lw=1.1, labels=False)
        ax1.plot([], [], "-", lw=1.1, color=colour, label=_spacing_label(spacing))
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
            ax1.plot(d_j, P_j, ":", lw=1.1, color=c)
            ax2.plot(P_j, a, ":", lw=1.1, color=c)
        ax1.plot([], [], "k:", label="JKR")
    ax1.plot([], [], "-", lw=0.5, color="0.5", label="loading (thin)")
    ax1.plot([], [], "o", mfc="white", mec="0.3", ms=3.5, label="after snap-off (jump)")
    ax1.set_xlabel(INDENT_LABEL)
    ax1.set_ylabel(FORCE_LABEL)
    ax2.set_xlabel(FORCE_LABEL)
    ax2.set_ylabel("contact radius $a$")
    if zoom and fmin < 0:
        # up to 4 pull-offs of compression, or the largest load if that is less (Fig. 4 at
        # 1/64-1/256 reached 0.1 on an axis running to 0.2)
        top = min(-4.0 * fmin, 1.05 * max(float(c["force"].max()) for c in curves.values()))
        ax1.set_ylim(1.3 * fmin, top)
        ax1.set_xlim(xmin - 0.1 * (xmax - xmin), xmax)
        ax2.set_xlim(1.3 * fmin, top)
    for ax in (ax1, ax2):
        ax.axhline(0, color="0.7", lw=0.5)
    ax1.legend(fontsize=6)
    sp = np.array(sorted(fmax_by))
    fm = np.array([fmax_by[s] for s in sp])
    ax3.loglog(sp, fm, "o-", color="tab:blue", ms=4, label="tfm $F_{max}$")
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
    fraction_ticks(ax3, sp)
    ax3.set_xlabel("spacing $\\Delta$")
    ax3.set_ylabel("$F_{max}$")
    ax3.legend(fontsize=6)
    tidy_ticks(ax1, ax2)
    letter((ax1, ax2, ax3))
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


@styled
def plot_jkr_scaling(k_data, r_data, k_fit, r_fit, coef_fit, path=None, title=None):
    """Paper Fig. 6: (a) F_max against K_th^2 (R = 1), (b) F_max against R. Points,
    the fitted line F = c K^2 R, the paper's 7.6 and JKR/LEFM's 3 pi^2/4.

    ``k_data`` / ``r_data``: DataFrames with columns k_th, radius, f_max. ``k_fit`` and
    ``r_fit`` are tfm.analysis.PowerLawFit, ``coef_fit`` a LineFit of F on K^2 R."""
    fig, (ax1, ax2) = figure(2)
    k2 = k_data["k_th"].to_numpy() ** 2
    ax1.plot(k2, k_data["f_max"], "o", ms=4, color="tab:blue", label="tfm")
    kk = np.linspace(0, k2.max() * 1.05, 50)
    r0 = float(k_data["radius"].iloc[0])
    ax1.plot(kk, coef_fit.slope * kk * r0, "-", color="tab:blue", lw=1,
             label=f"fit: $F = {coef_fit.slope:.2f}\\,K^2R$")
    ax1.plot(kk, theory.PAPER_COEFFICIENT * kk * r0, "--", color="tab:red", lw=1, label="paper: 7.6")
    ax1.plot(kk, theory.JKR_COEFFICIENT * kk * r0, ":", color="k", lw=1.2, label="JKR/LEFM: $3\\pi^2/4$ = 7.40")
    ax1.set_xlabel("$K_{th}^2$")
    ax1.set_ylabel("$F_{max}$")
    ax1.set_title(f"$R$ = {r0:g}; exponent of $K_{{th}}$: {k_fit.text(3)}")
    R = r_data["radius"].to_numpy()
    k0 = float(r_data["k_th"].iloc[0])
    ax2.plot(R, r_data["f_max"], "o", ms=4, color="tab:blue", label="tfm")
    rr = np.linspace(0, R.max() * 1.05, 50)
    ax2.plot(rr, r_fit.predict(np.maximum(rr, 1e-12)), "-", color="tab:blue", lw=1,
             label=f"power-law fit, exponent {r_fit.exponent:.3f}")
    ax2.plot(rr, theory.PAPER_COEFFICIENT * k0 ** 2 * rr, "--", color="tab:red", lw=1, label="paper: 7.6 $K^2R$")
    ax2.plot(rr, theory.JKR_COEFFICIENT * k0 ** 2 * rr, ":", color="k", lw=1.2, label="JKR/LEFM: 7.40 $K^2R$")
    ax2.set_xlabel("radius $R$")
    ax2.set_ylabel("$F_{max}$")
    ax2.set_title(f"$K_{{th}}$ = {k0:g}; exponent of $R$: {r_fit.text(3)}")
    for ax in (ax1, ax2):
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.legend(loc="upper left")
    tidy_ticks(ax1, ax2)
    letter((ax1, ax2))
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


@styled
def plot_kernel_study(summary, slopes, crossings, path=None, title=None):
    """Section 3.2: one panel per kernel with F_max against spacing (log-log, normalized
    by the coarsest spacing, one line per alpha), and a last panel with the spacing
    slope against alpha per kernel, the fitted line and its zero crossing alpha*."""
    from matplotlib import colormaps

    kernels = sorted(summary["p_kernel"].unique())
    n = len(kernels) + 1
    ncols = 2 if n > 3 else n
    nrows = math.ceil(n / ncols)
    fig, axes = figure(ncols, nrows, height=2.6 * nrows)
    for ax in axes[n:]:
        ax.set_visible(False)
    markers = {"boussinesq": "o", "local": "s", "neighbors": "^"}
    colours = {"boussinesq": "tab:blue", "local": "tab:green", "neighbors": "tab:orange"}
    cmap = colormaps["viridis"]
    for ax, kernel in zip(axes, kernels):
        part = summary[summary["p_kernel"] == kernel]
        alphas = sorted(part["p_alpha"].unique())
        spacings = sorted(part["p_spacing"].unique())
        for i, alpha in enumerate(alphas):
            g = part[part["p_alpha"] == alpha].sort_values("p_spacing")
            f0 = g["r_pull_off_force"].iloc[-1]
            ax.loglog(g["p_spacing"], g["r_pull_off_force"] / f0, "-", marker=markers.get(kernel, "o"), ms=3.5,
                      color=cmap(i / max(1, len(alphas) - 1)), label=f"$\\alpha$ = {alpha:g}")
        ax.axhline(1.0, color="0.6", lw=0.6)
        fraction_ticks(ax, spacings)
        plain_log_ticks(ax.yaxis)
        ax.set_xlabel("spacing $\\Delta$")
        ax.set_ylabel("$F_{max}$ / $F_{max}$(coarsest)")
        ax.set_title(f"{kernel} kernel")
        ax.legend(fontsize=6)
    ax2 = axes[len(kernels)]
    for kernel, g in slopes.groupby("p_kernel"):
        c = colours.get(kernel)
        ax2.errorbar(g["p_alpha"], g["slope"], yerr=[g["slope"] - g["ci_low"], g["ci_high"] - g["slope"]],
                     fmt=markers.get(kernel, "o"), color=c, ms=4, capsize=2,
                     label=f"{kernel}: $\\alpha^*$ = {crossings[kernel].text(3)}" if kernel in crossings else kernel)
        zc = crossings.get(kernel)
        if zc is not None:
            aa = np.linspace(g["p_alpha"].min() - 0.05, g["p_alpha"].max() + 0.05, 20)
            ax2.plot(aa, zc.intercept + zc.gradient * aa, "-", color=c, lw=0.8)
    # alpha* marked by a drop line from the crossing to the axis: a full-height line ran
    # through the legend's text
    bottom = ax2.get_ylim()[0]
    for kernel, zc in crossings.items():
        ax2.plot([zc.alpha, zc.alpha], [bottom, 0.0], color=colours.get(kernel), lw=0.6, ls=":")
    ax2.set_ylim(bottom=bottom)
    ax2.axhline(0, color="0.6", lw=0.6)
    ax2.set_xlabel("$\\alpha$")
    ax2.set_ylabel("d ln $F_{max}$ / d ln $\\Delta$")
    ax2.set_title("spacing slope; zero crossing = convergent $\\alpha$")
    ax2.legend(fontsize=6, loc="upper left")
    tidy_ticks(ax2)
    letter(axes[:n])
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)
