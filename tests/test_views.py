"""Figures and views of stored runs: `tfm plot`, `tfm show`, `tfm animate`, and the
faults a reviewer would see (captions, references, the snap-off jump, overlapping ticks)."""
import re
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tfm
from tfm import plots
from tfm.cli import main

STANDARD = dict(alpha=0.75, k_th=0.02, shape="paraboloid", radius=1.0, max_indent=0.05)


def _ticks_overlap(fig):
    """Pairs of visible tick labels on one axis whose boxes intersect (after drawing)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    bad = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels()
                     if t.get_visible() and t.get_text()]
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    if boxes[i].overlaps(boxes[j]):
                        bad.append((ax.get_xlabel() or ax.get_ylabel(), i, j))
    return bad


CASES = {
    # the default run's shape at a test-sized spacing; explicit F_th
    "sphere": dict(spacing=1 / 40, step=1e-3, max_indent=0.05),        # a_c = 3 spacings
    # the flat punch R = 0.3
    "flat_punch": dict(spacing=1 / 32, shape="flat_punch", radius=0.3, max_indent=0.01, step=1e-4),
    # the hexagonal layout with the tree operator at 1/64
    "hexagonal": dict(spacing=1 / 64, layout="hexagonal", operator="tree", step=1e-3),
}


def test_the_paper_figures_draw_a_curve(tmp_path):
    """`tfm paper` draws Figs. 2-5 only after all its campaigns: a figure function that
    raises (as plot_load_unload once did, on a name from plot_curve's signature) would
    be found hours in. Each must draw the curve it is given."""
    res = tfm.simulate(spacing=1 / 32, k_th=0.02, shape="paraboloid", max_indent=0.02, step=5e-4)
    curve, r = res.curve, res.params.radius
    figs = {"load_unload": plots.plot_load_unload(curve, r, k_ic=0.1, path=tmp_path / "3.png"),
            "hertz": plots.plot_hertz_validation({1 / 32: curve}, r, path=tmp_path / "2.png"),
            "refinement": plots.plot_refinement({1 / 32: curve}, r, k_ic=0.1, path=tmp_path / "4.png")}
    for name, fig in figs.items():
        drawn = [line for ax in fig.axes for line in ax.get_lines() if len(line.get_xdata()) >= 10]
        assert drawn, name
    assert all((tmp_path / f"{k}.png").stat().st_size > 10_000 for k in (2, 3, 4))
    # the refinement's zoom (4 pull-offs of compression) stops at the largest load when
    # that is less: Fig. 4's axes ran to twice the data
    top = curve["force"].max()
    assert top < -4 * curve["force"].min()
    ax1, ax2 = figs["refinement"].axes[:2]
    assert ax1.get_ylim()[1] == ax2.get_xlim()[1] == pytest.approx(1.05 * top)


@pytest.mark.parametrize("case", sorted(CASES))
def test_default_figure_renders_without_faults(case, tmp_path):
    res = tfm.simulate(**CASES[case])
    p = res.params
    fig = plots.plot_curve(res.curve, p, tmp_path / f"{case}.png")
    assert (tmp_path / f"{case}.png").stat().st_size > 10_000
    title = fig._suptitle.get_text()
    assert "alpha" not in title and "\\alpha" not in title      # explicit F_th: alpha plays no part
    assert f"1/{round(1 / p.spacing)}" in title and "delta_{max}" in title
    # one legend, on (a): (b) draws the same lines, and its box had no free corner there
    assert fig.axes[0].get_legend() is not None and fig.axes[1].get_legend() is None
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    if case in ("sphere", "hexagonal"):
        assert "Hertz (paraboloid approx.)" in labels
    else:
        assert any("flat punch" in lab for lab in labels)
        # (b)'s dashed a = R line had no name at all (no legend there)
        assert [t.get_text() for t in fig.axes[1].texts if "R" in t.get_text()] == ["$a = R$"]
    assert [t.get_text() for t in fig.texts][:2] == ["(a)", "(b)"] or \
        {"(a)", "(b)"} <= {t.get_text() for ax in fig.axes for t in ax.texts}
    # the unloading line stops at the last step in contact; the snap-off is a jump
    ax1 = fig.axes[0]
    unload = [ln for ln in ax1.get_lines() if ln.get_label() == "unload"][0]
    last = res.curve[(res.curve["phase"] == "unload") & (res.curve["n_contact"] > 0)].iloc[-1]
    assert unload.get_xdata()[-1] == last["indent"] and unload.get_ydata()[-1] == last["force"]
    assert _ticks_overlap(fig) == []


def test_the_legend_keeps_off_the_snap_off():
    """An adhesive flat punch (the issue's R = 0.25 at 1/32, preload 0.005): the legend
    placed "best" sat on the snap-off marker and its jump, which it cannot see (an
    annotation arrow); it now avoids both."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.path import Path as MPath

    res = tfm.simulate(spacing=1 / 32, shape="flat_punch", radius=0.25, k_th=0.02, max_indent=0.005, step=1e-4)
    fig = plots.plot_curve(res.curve, res.params)
    FigureCanvasAgg(fig).draw()
    ax = fig.axes[0]
    box = ax.get_legend().get_window_extent()
    marker = [ln for ln in ax.get_lines() if ln.get_label() == "snap-off (jump)"][0]
    at = ax.transData.transform(np.column_stack([marker.get_xdata(), marker.get_ydata()]))[0]
    assert not box.contains(*at)
    jump = [a for a in ax.texts if hasattr(a, "xyann")][0]
    ends = ax.transData.transform([jump.xyann, jump.xy])
    assert not MPath(ends).intersects_bbox(box, filled=False)


def test_the_convergent_alpha_marks_stay_below_the_legend():
    """Sec. 3.2's panel (d): the alpha* marks were full-height lines through the legend's
    text (upper left); they now drop from the zero crossing to the axis."""
    from types import SimpleNamespace

    summary = pd.DataFrame([dict(p_kernel="local", p_alpha=a, p_spacing=h, r_pull_off_force=(1 / h) ** (1 - a))
                            for a in (0.75, 1.0, 1.25) for h in (1 / 32, 1 / 64)])
    slopes = pd.DataFrame(dict(p_kernel="local", p_alpha=[0.75, 1.0, 1.25], slope=[-1.0, 0.0, 1.0],
                               ci_low=[-1.3, -0.3, 0.7], ci_high=[-0.7, 0.3, 1.3]))
    zc = SimpleNamespace(alpha=1.0, intercept=-4.0, gradient=4.0, text=lambda digits: "1.000 ± 0.010")
    fig = plots.plot_kernel_study(summary, slopes, {"local": zc})
    ax = fig.axes[-1]
    marks = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [1.0, 1.0]
    assert max(marks[0].get_ydata()) == 0.0 and min(marks[0].get_ydata()) == ax.get_ylim()[0]


def test_alpha_is_named_when_it_acts():
    p = tfm.Params(spacing=1 / 128, **STANDARD, f_th=None)
    text = plots.run_caption(p)
    assert "\\alpha$ = 0.75" in text and "K_{th}" in text and "1/128" in text and "paraboloid" in text


def test_an_si_caption_names_the_work_of_adhesion_and_the_units():
    """An SI record's threshold follows from gamma (k_th is None): the caption says so, with
    E, nu and the units, instead of failing on the missing K_th (it did until 2026-11-24)."""
    si = dict(units="si", youngs_modulus=1e6, poisson_ratio=0.5, radius=1e-3, shape="paraboloid",
              spacing=3.125e-5, max_indent=2e-5, step=1e-6)
    p = tfm.Params.from_dict(dict(si, work_of_adhesion=0.05))
    text = plots.run_caption(p)
    assert "\\gamma$ = 0.05 J/m$^2$" in text and "$E$ = $10^{6}$ Pa" in text and "\\nu$ = 0.5" in text
    assert "$R$ = 0.001 m" in text and "step $10^{-6}$ m" in text
    # and c, which sets K_th from gamma: runs at c = paper and c = 7 had the same caption
    # and pull-offs 12 % apart
    assert "$c$ = 7.6 (paper)" in text
    assert "$c$ = 7," in plots.run_caption(p.replace(k_th_coefficient=7.0))
    q = tfm.Params.from_dict(dict(si, f_th=2e-6, alpha=0))
    assert "$F_{th}$ = $2\\times10^{-6}$ N" in plots.run_caption(q)
    # the settings named only when set carry their units too (load_step = 10^-5 had none)
    r = q.replace(control="force", max_load=1e-3, load_step=1e-5, max_indent="auto", extent=2e-4)
    assert "load_step = $10^{-5}$ N" in plots.run_caption(r) and "extent = $2\\times10^{-4}$ m" in plots.run_caption(r)


def test_an_si_figure_draws_hertz_in_newtons_and_keeps_its_caption_inside():
    """The Hertz line of an SI run is P = 4/3 E* sqrt(R) delta^1.5 with E* = E/(1 - nu^2) in
    pascals (it was drawn in paper units, flat at zero against a curve in newtons), the axes
    name the units, and the long caption is broken into lines that fit the figure."""
    p = tfm.Params.from_dict(dict(units="si", youngs_modulus=2e6, poisson_ratio=0.3, radius=1e-3,
                                  shape="paraboloid", work_of_adhesion=0.05, spacing=3.125e-5,
                                  max_indent=2e-5, step=1e-6))
    delta = np.linspace(0, 2e-5, 5)
    curve = pd.DataFrame({"phase": ["load"] * 5, "indent": delta, "d": -delta, "force": delta,
                          "contact_radius": delta, "n_contact": 1})
    fig = plots.plot_curve(curve, p)
    ax1, ax2 = fig.axes[:2]
    hertz = [ln for ln in ax1.get_lines() if ln.get_label() == "Hertz"][0]
    d, P = hertz.get_xdata(), hertz.get_ydata()
    e_star = 2e6 / (1 - 0.3 ** 2)
    np.testing.assert_allclose(P, 4 / 3 * e_star * np.sqrt(1e-3) * d ** 1.5, rtol=1e-12)   # round-off only
    assert ax1.get_ylabel().startswith("force $P$ in N") and _no_offset(ax2.get_ylabel()).endswith("in m")
    caption = fig._suptitle.get_text()
    assert caption.count("\n") == 1 and caption.replace(",\n", ", ") == plots.run_caption(p)
    paper = tfm.Params.from_dict(dict(STANDARD, spacing=1 / 128))
    assert "\n" not in plots.plot_curve(curve, paper)._suptitle.get_text()


def test_captions_and_references_of_height_maps_rough_bodies_and_disorder(tmp_path):
    """A height-map record has no radius in its caption and no closed-form reference (the
    caption raised a KeyError, which failed tfm run after the table, and the flat punch's
    formula would have been drawn); roughness and threshold disorder are named, and the
    Hertz line of a rough body says that it is the smooth one."""
    np.save(tmp_path / "map.npy", np.zeros((40, 40)))
    hm = tfm.Params.from_dict(dict(shape="height_map", height_map=str(tmp_path / "map.npy"), map_pixel_size=1 / 20,
                                   spacing=1 / 16, f_th=0, max_indent=0.01, step=1e-3))
    text = plots.run_caption(hm)
    assert text.startswith("height map map.npy, $\\Delta$ = 1/16") and "$R$" not in text
    assert plots.reference_label(hm) is None
    rough = tfm.Params.from_dict(dict(STANDARD, spacing=1 / 32, rms_height=1e-3, roughness_seed=3,
                                      threshold_disorder="weibull", disorder_width=0.3, disorder_seed=2))
    text = plots.run_caption(rough)
    assert "rough ($H$ = 0.8, rms height 0.001, seed 3)" in text
    assert "weibull $F_{th}$ disorder 0.3 (seed 2)" in text
    assert plots.reference_label(rough) == "Hertz (smooth)"
    assert plots.reference_label(tfm.Params.from_dict(dict(STANDARD, spacing=1 / 32))) == "Hertz"
    # the rough punch's line did not say it was the smooth punch's
    punch = tfm.Params.from_dict(dict(shape="flat_punch", radius=0.5, spacing=1 / 32, f_th=0, rms_slope=0.1,
                                      max_indent=0.012, step=1e-4))
    assert plots.reference_label(punch) == "smooth punch, $P = 2E^*R\\delta$"
    assert plots.reference_label(punch.replace(rms_slope=0)) == "Boussinesq flat punch, $P = 2E^*R\\delta$"


def test_the_rough_punchs_figure_keeps_its_reference_within_the_runs_forces():
    """The smooth punch's a(P) line ran to 4x the rough punch's largest force and squeezed
    its curve into the left quarter of (b); the y label with its factor (x10^-3) ran past
    the top of (a) into the panel letter (a user's hunt). The factor now sits beside the
    unit and the note goes on a second line."""
    p = tfm.Params.from_dict(dict(shape="flat_punch", radius=0.5, spacing=1 / 32, f_th=0, rms_slope=0.1,
                                  short_cutoff=8 / 32, long_cutoff=0.5, max_indent=0.012, step=4e-4))
    res = tfm.simulate(p)
    fig = plots.plot_curve(res.curve, p)
    plots.fold_offsets(fig)
    ax1, ax2 = fig.axes[:2]
    pmax = res.curve["force"].max()
    # matplotlib's margins add 5 % of the data range on each side
    assert ax2.get_xlim()[1] <= pmax * 1.06 + 1e-12
    assert ax1.get_ylim()[1] > 2 * pmax         # (a) keeps the whole reference P(delta)
    label = ax1.get_ylabel()
    assert "\n(compression > 0)" in label and "10^{" in label.split("\n")[0]


def test_jkr_scaling_axis_has_no_overlapping_ticks():
    from tfm.analysis import fit_line, fit_power_law

    k = np.array([0.01, 0.02, 0.03, 0.04])
    f = 7.9 * k ** 2
    kd = pd.DataFrame({"k_th": k, "radius": 1.0, "f_max": f})
    rd = pd.DataFrame({"k_th": 0.04, "radius": [0.25, 0.5, 1, 2], "f_max": 7.9 * 0.04 ** 2 * np.array([0.25, 0.5, 1, 2])})
    fig = plots.plot_jkr_scaling(kd, rd, fit_power_law(k, f), fit_power_law(rd["radius"], rd["f_max"]),
                                 fit_line(k ** 2, f, through_origin=True))
    assert _ticks_overlap(fig) == []


def test_ratio_axes_of_about_a_decade_read_as_plain_numbers():
    """The kernel study's F_max ratio axes (0.25-4) were labelled 3×10⁻¹, 2×10⁰, 4×10⁰:
    Matplotlib's minor-tick labels on a log axis spanning about one decade."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig, (ax,) = plots.figure()
    ax.loglog([1 / 128, 1 / 32], [0.25, 3.6])
    plots.plain_log_ticks(ax.yaxis)
    FigureCanvasAgg(fig).draw()
    lo, hi = ax.get_ylim()
    labels = {t.get_text() for t in ax.yaxis.get_majorticklabels() + ax.yaxis.get_minorticklabels()
              if t.get_text() and lo <= t.get_position()[1] <= hi}
    assert {"1", "2", "3", "0.3"} <= labels, labels
    assert not any("times" in t or "^" in t or "e" in t for t in labels), labels


@pytest.fixture(scope="module")
def stored_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("views") / "curve.parquet"
    rc = main(["run", "--spacing", "1/64", "--alpha", "0.75", "--k-th", "0.02", "--shape", "paraboloid",
               "--max-indent", "0.05", "--snapshots", "5", "-o", str(out), "-q", "--no-plot"])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def si_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("si") / "si.parquet"
    assert main(["run", "--units", "si", "--youngs-modulus", "1e6", "--poisson-ratio", "0.5",
                 "--work-of-adhesion", "0.05", "--radius", "1e-3", "--shape", "paraboloid", "--spacing", "1e-5",
                 "--step", "5e-7", "--snapshots", "events", "-q", "--no-plot", "-o", str(out)]) == 0
    return out


def test_the_views_of_an_si_run_show_its_snapshots_in_newtons(si_run):
    """The views of an SI run show its snapshots in newtons (older files hold F*: scaled by F*)
    (they showed the marker at P = -7e-11 beside a curve in newtons, and F_th likewise).
    Against the SI curve table and the SI record: the same P at every stored step, to
    round-off (one multiplication each way), and F_th in newtons."""
    from tfm.units import force_scale
    from tfm.viewcli import _need_fields, load_run

    out = si_run
    curve, params, fpath = load_run(out)
    fields = _need_fields(out, fpath, params)
    assert force_scale(params) > 1e6                                  # F* in newtons: far from 1
    by_step = dict(zip(curve["step"], curve["force"]))
    for k in fields.steps:
        snap = fields.snapshot(int(k))
        assert snap["force"] == pytest.approx(by_step[int(k)], rel=1e-12, abs=1e-30)
        con = np.asarray(snap["state"]) == 1
        assert -float(np.asarray(snap["F"])[con].sum()) == pytest.approx(by_step[int(k)], rel=1e-9, abs=1e-15)
    assert float(np.nanmax(fields.f_th)) == pytest.approx(params.threshold_force, rel=1e-12)


def test_plot_and_show_from_a_stored_run(stored_run, capsys):
    assert main(["plot", str(stored_run.parent)]) == 0
    assert stored_run.with_suffix(".png").stat().st_size > 10_000
    assert main(["show", str(stored_run), "--step", "pull_off"]) == 0
    from tfm.snapshots import Fields

    k = Fields(stored_run.with_name("curve.fields.nc")).event_step("pull_off")
    assert stored_run.with_name(f"curve.step{k}.png").stat().st_size > 10_000
    assert main(["show", str(stored_run), "--step", "3"]) == 2        # not stored: says which are
    assert "nearest stored steps" in capsys.readouterr().err


def test_show_names_what_to_give_for_a_campaign_folder_and_one_step(stored_run, tmp_path, capsys):
    """`tfm show <campaign folder>` said "found 3; name the file", and each of the three
    tables named was refused; a second --step replaced the first without a word (a hunt)."""
    camp = tmp_path / "camp"
    (camp / "runs").mkdir(parents=True)
    (camp / "campaign.json").write_text("{}")
    for table in ("summary", "curves", "failures"):
        (camp / f"{table}.parquet").write_bytes(stored_run.read_bytes())
    assert main(["show", str(camp)]) == 2
    assert f"a campaign's folder; name one of its runs: {camp / 'runs'}/<run_id>.parquet" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["show", str(stored_run), "--step", "3", "--step", "5"])
    assert stop.value.code == 2 and "--step given twice ('3' and '5')" in capsys.readouterr().err


def test_a_run_without_a_pull_off_says_why_and_which_events_it_has(tmp_path, capsys):
    """`tfm show` of a run with no adhesion said only "no pull_off snapshot stored"; and the
    event names were not read like every other named value (" MAX_LOAD " was refused)."""
    out = tmp_path / "plain.parquet"
    assert main(["run", "--spacing", "1/32", "--f-th", "0", "--shape", "paraboloid", "--max-indent", "0.05",
                 "--step", "1e-3", "--snapshots", "events", "-q", "--no-plot", "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["show", str(out)]) == 2                               # the default event: pull_off
    err = capsys.readouterr().err
    assert "no pull_off snapshot: the run never pulled" in err and "stored events: max_load (step " in err
    assert main(["show", str(out), "--step", " MAX_LOAD "]) == 0
    # an adhesive run that max_unload_steps stopped before any tension was blamed on "no
    # adhesion" (a hunt)
    cut = tmp_path / "cut.parquet"
    assert main(["run", "--spacing", "1/32", "--k-th", "0.02", "--shape", "paraboloid", "--max-indent", "0.05",
                 "--step", "1e-3", "--snapshots", "events", "--max-unload-steps", "20", "-q", "--no-plot",
                 "-o", str(cut)]) == 3
    capsys.readouterr()
    assert main(["show", str(cut)]) == 2
    err = capsys.readouterr().err
    assert "no pull_off snapshot: unloading stopped at max_unload_steps" in err and "no adhesion" not in err


@pytest.mark.parametrize("view", [["plot"], ["show", "--step", "pull_off"]])
def test_a_file_given_with_o_is_replaced_only_with_overwrite(stored_run, tmp_path, capsys, view):
    """`tfm plot RUN -o mine.png` replaced an existing mine.png without a word, where
    `tfm run` asks for --overwrite. The default beside the run is its own figure, redrawn."""
    mine = tmp_path / "mine.png"
    mine.write_bytes(b"someone's figure")
    argv = [view[0], str(stored_run), *view[1:], "-o", str(mine)]
    assert main(argv) == 2
    assert "mine.png exists; pass --overwrite to replace it" in capsys.readouterr().err
    assert mine.read_bytes() == b"someone's figure"
    assert main([*argv, "--overwrite"]) == 0 and mine.stat().st_size > 10_000
    assert main([view[0], str(stored_run), *view[1:]]) == 0 == main([view[0], str(stored_run), *view[1:]])


def test_animate_makes_a_gif_with_one_frame_per_unloading_snapshot(stored_run, tmp_path):
    from PIL import Image

    from tfm.snapshots import Fields

    out = tmp_path / "unload.gif"
    assert main(["animate", str(stored_run), "-o", str(out)]) == 0
    curve = pd.read_parquet(stored_run)
    phase = dict(zip(curve["step"], curve["phase"]))
    steps = Fields(stored_run.with_name("curve.fields.nc")).steps
    expected = sum(phase[s] == "unload" for s in steps) + 1          # + the last loading step
    gif = Image.open(out)
    assert gif.n_frames == expected
    # one palette for every frame: a force has one colour throughout (each frame had its
    # own, and the colour bar's colours moved by up to 82/255 from frame to frame)
    rgb = []
    for i in range(gif.n_frames):
        gif.seek(i)
        rgb.append(np.asarray(gif.convert("RGB")))
    # so the whole animation uses at most one palette's 256 colours
    used = set().union(*(map(tuple, frame.reshape(-1, 3)) for frame in rgb))
    assert len(rgb) > 1 and len(used) <= 256, len(used)


def test_animate_thins_many_snapshots_to_max_frames_and_keeps_the_events(stored_run, tmp_path, capsys):
    """1257 snapshots made a GIF of 1257 frames, in four minutes and 900 MB (a user's hunt);
    then --max-frames 10 made 13 frames and --max-frames 2 five: the first, the last and
    the events came on top of the stride (another)."""
    from PIL import Image

    from tfm.snapshots import EVENTS, Fields
    from tfm.viewcli import FRAME_EVENTS, event_steps, frame_plan, frame_steps

    assert set(FRAME_EVENTS) == set(EVENTS)
    fields = Fields(stored_run.with_name("curve.fields.nc"))
    steps = frame_steps(fields, pd.read_parquet(stored_run))
    events = [s for s in event_steps(fields) if s in steps]
    assert len(steps) > 10 and len(events) >= 2
    for cap in range(2, len(steps)):
        thin, k = frame_plan(steps, cap, keep=event_steps(fields))
        must = {steps[0], steps[-1], *events}
        assert len(thin) <= cap and thin == sorted(set(thin)) and set(thin) <= set(steps)
        if k:       # every k-th, the first, the last and the events, nothing else; k the smallest
            assert thin == [s for i, s in enumerate(steps) if i % k == 0 or s in must]
            assert k == 1 or len([s for i, s in enumerate(steps) if i % (k - 1) == 0 or s in must]) > cap
        else:       # no room for a stride: the first, the last, then the events by priority
            assert len(must) >= cap and thin[0] == steps[0] and thin[-1] == steps[-1]
            assert len(thin) == cap and (cap < 3 or events[0] in thin)
    assert frame_plan(steps, 0)[0] == steps == frame_plan(steps, len(steps))[0]
    out = tmp_path / "thin.gif"
    for cap in (8, 2):
        thin, k = frame_plan(steps, cap, keep=event_steps(fields))
        assert main(["animate", str(stored_run), "-o", str(out), "--max-frames", str(cap), "--overwrite"]) == 0
        err = capsys.readouterr().err
        assert f"{len(thin)} frames" in err and f"{len(steps)} snapshots to animate, more than --max-frames {cap}" in err
        assert ("only the first, the last and the events" in err) == (k == 0)
        assert Image.open(out).n_frames == len(thin) <= cap
    for bad in ("-1", "1"):
        assert main(["animate", str(stored_run), "-o", str(out), "--max-frames", bad, "--overwrite"]) == 2
        assert "--max-frames:" in capsys.readouterr().err


def test_a_failed_animation_leaves_the_earlier_one_whole(stored_run, tmp_path, monkeypatch, capsys):
    """A write that failed with --overwrite (an fps too low for a GIF, then) left the old
    GIF truncated to 416 unreadable bytes."""
    from PIL import Image

    from tfm import viewcli

    out = tmp_path / "keep.gif"
    assert main(["animate", str(stored_run), "-o", str(out)]) == 0
    before = out.read_bytes()

    def broken(*a, **k):
        Path(a[3]).write_bytes(b"GIF89a half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(viewcli, "_write_animation", broken)
    assert main(["animate", str(stored_run), "-o", str(out), "--overwrite"]) == 1
    assert "No space left on device" in capsys.readouterr().err
    assert out.read_bytes() == before and Image.open(out).n_frames > 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.gif"]


def test_an_ffmpeg_that_fails_is_reported_not_taken_for_a_closed_stdout(stored_run, tmp_path, monkeypatch, capsys):
    """ffmpeg present but failing (here a stand-in that exits at once): its broken pipe was
    taken for tfm's own stdout's, and `tfm animate -o a.mp4` ended with status 141 and not
    a word (a user's hunt)."""
    import os

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "ffmpeg"
    fake.write_text("#!/bin/sh\necho 'fake ffmpeg: unsupported encoder' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    out = tmp_path / "a.mp4"
    assert main(["animate", str(stored_run), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "ffmpeg failed to write .mp4" in err and "write a .gif instead" in err, err
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["bin"]


def test_animate_and_show_a_table_whose_record_does_not_rebuild(stored_run, tmp_path, capsys):
    """A height map moved after its run: tfm animate wrote the GIF, then stopped with an
    AttributeError on the missing record."""
    import json
    import shutil

    import pyarrow.parquet as pq

    copy = tmp_path / "c.parquet"
    table = pq.read_table(stored_run)
    meta = dict(table.schema.metadata)
    params = {**json.loads(meta[b"tfm.params"]), "spacing": -1}      # a record that cannot rebuild
    meta[b"tfm.params"] = json.dumps(params).encode()
    pq.write_table(table.replace_schema_metadata(meta), copy)
    shutil.copy(stored_run.with_name("curve.fields.nc"), tmp_path / "curve.fields.nc")
    assert main(["animate", str(copy)]) == 0
    err = capsys.readouterr().err
    assert "does not rebuild" in err and "frames" in err and copy.with_suffix(".gif").exists()


def test_a_table_renamed_with_its_snapshots_still_finds_them(stored_run, tmp_path, capsys):
    """Renamed together (g.parquet, g.fields.nc), the table was said to have stored no
    snapshots, with advice to rerun it; deleted, the same."""
    import shutil

    table, fields = tmp_path / "g.parquet", tmp_path / "g.fields.nc"
    shutil.copy(stored_run, table)
    shutil.copy(stored_run.with_name("curve.fields.nc"), fields)
    assert main(["show", str(table), "--step", "pull_off"]) == 0
    fields.unlink()
    assert main(["show", str(table)]) == 2
    err = capsys.readouterr().err
    assert "the run stored field snapshots, but they are not beside the table" in err
    assert "curve.fields.nc and g.fields.nc" in err


def test_a_renamed_table_finds_its_snapshots_when_its_old_name_holds_a_newer_runs(stored_run, tmp_path, capsys):
    """Renamed with its snapshots (keep.parquet, keep.fields.nc), then a new run written
    under the old name: the table's recorded name (curve.fields.nc) now held the new run's
    snapshots, its own keep.fields.nc was never tried, and it was refused as stale with
    advice to rerun it (a user's hunt)."""
    import shutil

    keep = tmp_path / "keep.parquet"
    shutil.copy(stored_run, keep)
    shutil.copy(stored_run.with_name("curve.fields.nc"), tmp_path / "keep.fields.nc")
    newer = tmp_path / "curve.parquet"                 # another run under the recorded name
    assert main(["run", "--spacing", "1/32", "--k-th", "0.03", "--shape", "paraboloid", "--max-indent", "0.05",
                 "--step", "1e-3", "--snapshots", "events", "-q", "--no-plot", "-o", str(newer)]) == 0
    capsys.readouterr()
    assert main(["show", str(keep), "--step", "pull_off", "-o", str(tmp_path / "k.png")]) == 0
    # and with no snapshots of its own beside it, the newer run's are still refused
    (tmp_path / "keep.fields.nc").unlink()
    assert main(["show", str(keep), "-o", str(tmp_path / "k2.png")]) == 2
    assert "stale, from an earlier run" in capsys.readouterr().err


def test_a_renamed_table_finds_its_snapshots_when_its_old_name_holds_a_damaged_file(stored_run, tmp_path, capsys):
    """Renamed with its snapshots (keep.parquet, keep.fields.nc) and the recorded name
    (curve.fields.nc) left damaged: "not a readable field snapshots file" without trying
    the table's own, good file. Alone, the damaged file is still named as such."""
    import shutil

    keep = tmp_path / "keep.parquet"
    shutil.copy(stored_run, keep)
    shutil.copy(stored_run.with_name("curve.fields.nc"), tmp_path / "keep.fields.nc")
    (tmp_path / "curve.fields.nc").write_bytes(b"not a NetCDF file" * 64)
    assert main(["show", str(keep), "--step", "pull_off", "-o", str(tmp_path / "k.png")]) == 0
    (tmp_path / "keep.fields.nc").unlink()
    capsys.readouterr()
    assert main(["show", str(keep), "-o", str(tmp_path / "k2.png")]) == 2
    assert "curve.fields.nc: not a readable field snapshots file" in capsys.readouterr().err


def test_a_damaged_snapshot_or_an_output_that_cannot_be_replaced_is_one_line(stored_run, tmp_path, capsys):
    """A chunk of F damaged on disk gave h5py's OSError as a traceback; so did a figure that
    could not be replaced (read-only folder), after the drawing. Both are one line, exit 1,
    and the earlier figure is left whole."""
    import os
    import shutil

    import h5py

    table, fields = tmp_path / "d.parquet", tmp_path / "d.fields.nc"
    shutil.copy(stored_run, table)
    shutil.copy(stored_run.with_name("curve.fields.nc"), fields)
    with h5py.File(fields, "r") as f:
        info = [f["F"].id.get_chunk_info(i) for i in range(f["F"].id.get_num_chunks())]
    raw = bytearray(fields.read_bytes())
    for c in info:                                     # every chunk of F: whatever step is drawn
        for k in range(c.byte_offset + 8, c.byte_offset + min(c.size, 64)):
            raw[k] ^= 0xFF
    fields.write_bytes(bytes(raw))
    assert main(["show", str(table), "--step", "pull_off", "-o", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert "cannot be read" in err and "the file is damaged" in err and "Traceback" not in err
    # a figure that cannot be replaced (an immutable file: chattr +i); faked, since the
    # tests may run as root, for whom read-only folders are writable
    shutil.copy(stored_run, tmp_path / "c.parquet")
    assert main(["plot", str(tmp_path / "c.parquet")]) == 0
    before = (tmp_path / "c.png").read_bytes()

    def refused(src, dst):
        raise PermissionError(1, "Operation not permitted", str(dst))

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(os, "replace", refused)
        capsys.readouterr()
        assert main(["plot", str(tmp_path / "c.parquet")]) == 1
    err = capsys.readouterr().err
    assert f"tfm: error: {tmp_path / 'c.png'}: Operation not permitted" in err and "Traceback" not in err
    assert (tmp_path / "c.png").read_bytes() == before and not list(tmp_path.glob(".c.*"))


def test_show_without_snapshots_says_how_to_get_them(tmp_path, capsys):
    out = tmp_path / "c.parquet"
    tfm.simulate(spacing=1 / 16, step=2e-3, **STANDARD).write_curve(out)
    assert main(["show", str(out)]) == 2
    assert "--snapshots events" in capsys.readouterr().err


# ---- views refuse what is not one run's curve with its own snapshots ---------------------
TINY = ["--spacing", "1/16", "--step", "2e-3", "--k-th", "0.02", "--shape", "paraboloid",
        "--max-indent", "0.05", "-q", "--no-plot"]


def _set_fields_run_id(path, run_id):
    import h5py

    with h5py.File(path, "r+") as f:
        f.attrs["run_id"] = run_id


def test_show_and_animate_refuse_the_snapshots_of_another_run(tmp_path, capsys):
    """A fields file left beside a table by an earlier run (a rerun to the same -o without
    snapshots) was drawn with the new curve. The views compare the run ids."""
    from tfm.results import read_metadata

    old, new = tmp_path / "old.parquet", tmp_path / "new.parquet"
    assert main(["run", *TINY, "--snapshots", "events", "-o", str(old)]) == 0
    assert main(["run", *TINY, "--radius", "2", "-o", str(new)]) == 0
    stale = new.with_name("new.fields.nc")
    stale.write_bytes(old.with_name("old.fields.nc").read_bytes())
    old_id, new_id = read_metadata(old)["run_id"], read_metadata(new)["run_id"]
    for argv in (["show", str(new)], ["animate", str(new), "-o", str(tmp_path / "a.gif")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert old_id in err and new_id in err and str(stale) in err
    assert not list(tmp_path.glob("*.png")) and not (tmp_path / "a.gif").exists()
    assert main(["show", str(old), "-o", str(tmp_path / "own.png")]) == 0      # its own snapshots: drawn


def test_an_si_runs_snapshots_are_its_own_under_either_run_id(si_run, tmp_path):
    """The fields file of an SI run holds the paper-units twin's run id today (the SI run's
    own once the writer records it): both are the run's; any other is refused."""
    from tfm.units import to_paper
    from tfm.viewcli import ViewError, _need_fields, load_run

    out = tmp_path / "si.parquet"
    out.write_bytes(si_run.read_bytes())
    fields = out.with_name("si.fields.nc")
    fields.write_bytes(si_run.with_name("si.fields.nc").read_bytes())
    curve, params, fpath = load_run(out)
    for run_id in (to_paper(params).run_id, params.run_id):
        _set_fields_run_id(fields, run_id)
        assert _need_fields(out, fpath, params).attrs["run_id"] == run_id
    _set_fields_run_id(fields, "0123456789abcdef")
    with pytest.raises(ViewError, match="0123456789abcdef"):
        _need_fields(out, fpath, params)


def test_views_refuse_a_campaigns_joined_curves_and_its_summary(tmp_path, capsys):
    """A campaign's curves.parquet (all runs, a run_id column) was drawn as one line through
    every run with exit 0, and its summary.parquet raised KeyError: 'phase'. Both are refused
    with the per-run tables (runs/<run_id>.parquet) named instead."""
    from tfm.results import write_table

    res = tmp_path / "smoke"
    curve = tfm.simulate(spacing=1 / 16, step=2e-3, **STANDARD).curve
    joined = pd.concat([curve.assign(run_id=rid) for rid in ("aaaaaaaaaaaaaaaa", "bbbbbbbbbbbbbbbb")])
    write_table(joined[["run_id", *curve.columns]], res / "curves.parquet", extra={"campaign": {"name": "smoke"}})
    write_table(pd.DataFrame({"run_id": ["aaaaaaaaaaaaaaaa", "bbbbbbbbbbbbbbbb"], "status": "done"}),
                res / "summary.parquet", extra={"campaign": {"name": "smoke"}})
    (res / "runs").mkdir()
    for name, says in (("curves", "holds the curves of 2 runs"), ("summary", "without the curve columns")):
        out = tmp_path / f"{name}.png"
        assert main(["plot", str(res / f"{name}.parquet"), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert says in err and f"{res / 'runs'}/<run_id>.parquet" in err and "Traceback" not in err
        assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["plot", "{run}", "-o", "{tmp}/x.txt"], "x.txt must end with .png or .pdf or .svg"),
    (["show", "{run}", "-o", "{tmp}/x.jpg"], "x.jpg must end with .png or .pdf or .svg"),
    (["animate", "{run}", "-o", "{tmp}/x.webm"], "x.webm must end with .gif or .mp4"),
    (["animate", "{run}", "-o", "{tmp}/x.gif", "--fps", "0"], "--fps 0: expected 0.01 <= fps <= 50 for a GIF"),
    (["animate", "{run}", "-o", "{tmp}/x.gif", "--fps", "-3"], "--fps -3: expected 0.01 <= fps <= 50"),
    (["animate", "{run}", "-o", "{tmp}/x.gif", "--fps", "500"], "--fps 500: expected 0.01 <= fps <= 50"),
    # 1 cs frames (67 to 100 fps) played at 10 fps in browsers (a user's hunt)
    (["animate", "{run}", "-o", "{tmp}/x.gif", "--fps", "100"],
     "--fps 100: expected 0.01 <= fps <= 50 for a GIF (viewers play faster GIF frames at 10 fps"),
    (["animate", "{run}", "-o", "{tmp}/x.mp4", "--fps", "nan"], "--fps nan: expected a finite fps >= 0.01"),
    (["plot", "{tmp}/garbage.parquet", "-o", "{tmp}/x.png"], "garbage.parquet: not a readable Parquet table"),
    (["show", "{tmp}/garbage.parquet", "-o", "{tmp}/x.png"], "garbage.parquet: not a readable Parquet table"),
    # a mistyped folder was made silently; `tfm run -o` refuses it
    (["plot", "{run}", "-o", "{tmp}/nodir/x.png"], "the folder {tmp}/nodir does not exist (create it first)"),
])
def test_bad_view_arguments_exit_2_before_drawing(stored_run, tmp_path, capsys, argv, message):
    """An output suffix no writer takes, an fps the GIF cannot store (int(1000 / fps) ms in
    whole centiseconds is 0 above 100 fps; 0 divided by zero) and a file that is not Parquet
    were tracebacks, some after the drawing."""
    (tmp_path / "garbage.parquet").write_bytes(b"not a parquet file\n" * 10)
    argv = [a.format(run=stored_run, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message.format(tmp=tmp_path) in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.parquet"]      # nothing drawn


def test_the_fps_range_is_what_a_gif_can_store():
    from tfm.viewcli import DEFAULT_FPS, GIF_MAX_FPS, ViewError, check_fps, gif_centiseconds

    # the default plays as given: 8 fps played at 8.33, with a note on every plain animate
    assert 100 / gif_centiseconds(DEFAULT_FPS) == DEFAULT_FPS

    from tfm.viewcli import gif_centiseconds

    check_fps(GIF_MAX_FPS, "a.gif")
    assert gif_centiseconds(GIF_MAX_FPS) >= 2                # viewers play 0 and 1 cs frames at 10 cs
    with pytest.raises(ViewError):
        check_fps(GIF_MAX_FPS * 1.01, "a.gif")
    check_fps(120, "a.mp4")                                  # MP4 stores the rate itself
    # at the other end, a GIF frame lasts at most 65535 cs: 0.001 fps crashed the writer
    # (OverflowError) after the old file had been truncated
    from tfm.viewcli import MIN_FPS
    check_fps(MIN_FPS, "a.gif")
    assert gif_centiseconds(MIN_FPS) <= 65535
    for fps in (0.001, MIN_FPS * 0.99):
        with pytest.raises(ViewError):
            check_fps(fps, "a.gif")


# ---- contact maps: units, colour bar, contact line ----------------------------------------
def _no_offset(label):
    """An axis label without the common factor that plots.fold_offsets adds on saving."""
    return re.sub(r" \(\$\\times[^)]*\)", "", label).replace("\n", " ")     # a y label's note: 2nd line


def test_a_common_factor_goes_into_its_axis_label(stored_run, tmp_path):
    """The ×10⁻² of a y axis sat above it and ran into the panel's title (results/paper
    fig6, panel b); like the x axis' below it, it is now part of the label."""
    from tfm.viewcli import load_run

    curve, params, _ = load_run(stored_run)
    fig = plots.plot_curve(curve, params, tmp_path / "c.png")
    folded = []
    for ax in fig.axes:
        for axis, label in ((ax.xaxis, ax.get_xlabel()), (ax.yaxis, ax.get_ylabel())):
            offset = axis.get_major_formatter().get_offset()
            if offset:
                # a y label's note goes on a second line, after the factor
                assert label.endswith(f"({offset})") or f"({offset})\n(" in label
                assert not axis.get_offset_text().get_visible()
                folded.append(axis.axis_name)
    assert "y" in folded                  # forces of order 1e-3: the y axes have a factor


def test_show_and_animate_of_an_si_run_name_the_units_like_tfm_plot(si_run, monkeypatch, tmp_path):
    """The contact map's axes and colour bar, the curve panel beside it and the snapshot
    title of an SI run had no units; the curve panel now has tfm plot's labels exactly."""
    from tfm import viewcli
    from tfm.viewcli import _need_fields, load_run

    curve, params, fpath = load_run(si_run)
    fields = _need_fields(si_run, fpath, params)
    snap = fields.snapshot(fields.event_step("pull_off"))
    reference = plots.plot_curve(curve, params).axes[0]

    def assert_units(fig):
        ax_map, ax_curve, cbar = fig.axes[:3]
        assert (_no_offset(ax_map.get_xlabel()), _no_offset(ax_map.get_ylabel())) == ("$x$ in m", "$y$ in m")
        assert cbar.get_ylabel() == "spring force $F$ in N (tension > 0)"
        assert re.fullmatch(r"\$F_\{th\}\$ = .* N", cbar.get_title(loc="left"))    # the threshold's value too
        assert _no_offset(ax_curve.get_ylabel()) == _no_offset(reference.get_ylabel()) == \
            "force $P$ in N (compression > 0)"
        assert _no_offset(ax_curve.get_xlabel()) == _no_offset(reference.get_xlabel()) == "indentation $\\delta = -d$ in m"
        title = fig._suptitle.get_text().splitlines()[-1]
        assert re.search(r"\$\\delta\$ = .* m, \$P\$ = .* N, ", title), title

    assert_units(plots.plot_contact_map(fields, snap, curve, params))
    figures = []
    real = plots.map_figure
    monkeypatch.setattr(plots, "map_figure", lambda *a, **k: figures.append(real(*a, **k)) or figures[-1])
    viewcli.animate(fields, curve, params, tmp_path / "si.gif")
    assert_units(figures[0][0])


def test_paper_unit_contact_maps_name_the_paper_units(stored_run):
    """A paper-units run's axes had no unit at all, where an SI run's say m and N and the
    snapshot file says L* and F* (a hunt)."""
    from tfm.viewcli import _need_fields, load_run

    curve, params, fpath = load_run(stored_run)
    fields = _need_fields(stored_run, fpath, params)
    fig = plots.plot_contact_map(fields, fields.snapshot(fields.event_step("pull_off")), curve, params)
    ax_map, ax_curve, cbar = fig.axes[:3]
    assert (ax_map.get_xlabel(), ax_map.get_ylabel()) == ("$x$ in $L^*$", "$y$ in $L^*$")
    assert cbar.get_ylabel() == "spring force $F$ in $F^*$ (tension > 0)"
    assert (_no_offset(ax_curve.get_xlabel()), _no_offset(ax_curve.get_ylabel())) == \
        ("indentation $\\delta = -d$ in $L^*$", "force $P$ in $F^*$ (compression > 0)")
    assert " m," not in fig._suptitle.get_text() and " N," not in fig._suptitle.get_text()


def _square_fields(f_th):
    """A 21 x 21 square grid (spacing 0.1) in contact within r < 0.55, forces from -1 at
    the centre to the thresholds at the edge of the contact."""
    from types import SimpleNamespace

    x = np.linspace(-1, 1, 21)
    X, Y = np.meshgrid(x, x, indexing="ij")
    con = np.hypot(X, Y) < 0.55
    F = np.where(con, -1.0 + np.hypot(X, Y), 0.0)
    fields = SimpleNamespace(grid=True, x=x, y=x, f_th=np.broadcast_to(f_th, X.shape), params={"spacing": 0.1})
    return fields, {"F": F, "state": np.where(con, 1, 2)}


def _colour_bar(f_th):
    fig, (ax,) = plots.figure(1)
    cmap = plots.ContactMap(ax, *_square_fields(f_th))
    cbar = fig.axes[-1]
    return cmap, cbar, [t.get_text() for t in cbar.get_yticklabels()]


def test_the_colour_bar_says_max_f_th_when_thresholds_vary():
    """With threshold disorder the bar ends at the largest threshold: it was labelled as
    if it were the threshold."""
    rng = np.random.default_rng(0)
    varied = 0.1 * (1 + 0.3 * rng.random((21, 21)))
    _, cbar, labels = _colour_bar(varied)
    assert labels[-1] == "max $F_{th}$"
    assert cbar.get_title(loc="left") == f"max $F_{{th}}$ = {plots.number(varied.max(), 2)}"
    _, cbar, labels = _colour_bar(0.1)
    assert labels[-1] == "$F_{th}$" and cbar.get_title(loc="left") == f"$F_{{th}}$ = {plots.number(0.1, 2)}"


def test_the_colour_bar_label_sits_beside_its_tick_labels():
    """The threshold's value as the top tick label ('F_th = 1.1 x 10^-4') was the widest
    label by far and pushed the bar's label away from the bar: the value is above the bar."""
    cmap, cbar, labels = _colour_bar(1.1e-4)
    renderer = cbar.figure.canvas.get_renderer()
    widths = [t.get_window_extent(renderer).width for t in cbar.get_yticklabels()]
    assert widths[-1] <= max(widths[:-1])


def test_the_colour_bar_of_a_run_without_adhesion_has_no_tension_half():
    """F_th = 0: the bar's tension half spanned 0 to 1e-300, half the bar, with the F_th
    label on the 0 tick. Now it runs from the most compressive force to 0, white at 0."""
    import matplotlib as mpl

    cmap, cbar, labels = _colour_bar(0.0)
    assert (cmap.norm.vmin, cmap.norm.vmax) == (-1.0, 0.0)
    assert cbar.get_ylim() == (-1.0, 0.0)
    assert not any("F_{th}" in t for t in labels) and labels[-1] == "0"
    white = mpl.colormaps[plots.CONTACT_CMAP](0.5)
    assert np.allclose(cmap.image.cmap(cmap.norm(0.0)), white)
    assert np.allclose(cmap.image.cmap(cmap.norm(-1.0)), mpl.colormaps[plots.CONTACT_CMAP](0.0))


def _line_vertices(artist):
    if hasattr(artist, "get_paths"):
        return np.concatenate([p.vertices for p in artist.get_paths() if len(p.vertices)])
    return artist.get_xydata()


@pytest.mark.parametrize("layout", ["square", "hexagonal", "jittered"])
def test_the_contact_line_runs_between_contact_and_free_springs(layout):
    """On hexagonal and jittered layouts the contact line joined the outermost contact
    spring of each angle bin: it ran through contact springs and spiked into the contact.
    It now separates the contact set from the rest, as on the square grid: it encloses
    every spring in contact and no other, and each of its points lies within one spacing
    of both a contact and a free spring."""
    from types import SimpleNamespace

    from matplotlib.path import Path as MPath
    from scipy.spatial import cKDTree

    from tfm import geometry

    a = 1 / 32
    lay = {"square": lambda: geometry.square_grid(a, 0.5), "hexagonal": lambda: geometry.hexagonal_grid(a, 0.5),
           "jittered": lambda: geometry.jittered_grid(a, 0.5, 0.25, 1)}[layout]()
    con = np.hypot(lay.x, lay.y + 0.03) < 0.21
    state = np.where(con, 1, 2)
    if layout == "square":
        n = lay.shape[0]
        x = lay.x.reshape(n, n)[:, 0]
        fields = SimpleNamespace(grid=True, x=x, y=x, f_th=np.full((n, n), 0.1), params={"spacing": a})
        snap = {"F": np.zeros((n, n)), "state": state.reshape(n, n)}
    else:
        fields = SimpleNamespace(grid=False, x=lay.x, y=lay.y, f_th=np.full(lay.n, 0.1), params={"spacing": a})
        snap = {"F": np.zeros(lay.n), "state": state}
    fig, (ax,) = plots.figure(1)
    line = plots.ContactMap(ax, fields, snap, colorbar=False).contour
    loop = MPath(_line_vertices(line))
    pts = np.column_stack([lay.x, lay.y])
    inside = loop.contains_points(pts)
    assert inside[con].all() and not inside[~con].any()
    v = _line_vertices(line)
    assert (cKDTree(pts[con]).query(v)[0] < a).all() and (cKDTree(pts[~con]).query(v)[0] < a).all()


@pytest.mark.parametrize("layout", ["hexagonal", "jittered"])
def test_off_grid_contact_maps_draw_each_spring_as_its_own_cell(layout):
    """Hexagonal and jittered maps drew each spring as a marker sized in points for a
    guessed panel width: about 1.8 spacings across, so the painted contact reached past the
    contact line (a user's hunt). Each spring is now its cell in data units, the Voronoi
    cell on both layouts (the hexagon on the lattice): it holds its spring and no other,
    and the cells tile the plane."""
    from types import SimpleNamespace

    from matplotlib.path import Path as MPath

    from tfm import geometry

    a = 1 / 32
    lay = geometry.hexagonal_grid(a, 0.3) if layout == "hexagonal" else geometry.jittered_grid(a, 0.3, 0.25, 1)
    params = {"spacing": a, "layout": layout}
    pts = np.column_stack([lay.x, lay.y])
    cells = plots.spring_cells(lay.x, lay.y, params)
    assert len(cells) == lay.n
    inner = np.flatnonzero(np.hypot(lay.x, lay.y) < 0.2)
    area = 0.0
    for i in inner:
        path = MPath(cells[i])
        holds = path.contains_points(pts)
        assert holds[i] and holds.sum() == 1
        assert np.hypot(*(cells[i] - pts[i]).T).max() <= a       # a cell is about one spacing
        xc, yc = cells[i].T
        area += 0.5 * abs(np.dot(xc, np.roll(yc, 1)) - np.dot(yc, np.roll(xc, 1)))
    if layout == "hexagonal":       # the lattice's Voronoi cell, exactly
        assert area == pytest.approx(inner.size * np.sqrt(3) / 2 * a * a, rel=1e-12)
    # they tile: a point well inside lies in exactly one cell (no gap, no overlap)
    probe = np.random.default_rng(0).uniform(-0.12, 0.12, (2000, 2))
    hits = np.array([MPath(cells[i]).contains_points(probe) for i in inner]).sum(axis=0)
    assert (hits == 1).all()
    # the map paints those cells
    state = np.where(np.hypot(lay.x, lay.y) < 0.15, 1, 2)
    fields = SimpleNamespace(grid=False, x=lay.x, y=lay.y, f_th=np.full(lay.n, 0.1), params=params)
    fig, (ax,) = plots.figure(1)
    image = plots.ContactMap(ax, fields, {"F": np.zeros(lay.n), "state": state}, colorbar=False).image
    assert len(image.get_paths()) == lay.n
    assert np.allclose(image.get_paths()[0].vertices[:len(cells[0])], cells[0])


def test_a_record_that_does_not_rebuild_is_named_not_silently_dropped(tmp_path, capsys):
    """A height-map run whose map has moved: the figure is drawn without its caption, and
    the views say why (the caption vanished without a word)."""
    m = tmp_path / "map.npy"
    np.save(m, np.zeros((41, 41)))
    out = tmp_path / "hm.parquet"
    assert main(["run", "--shape", "height_map", "--height-map", str(m), "--map-pixel-size", "1/32",
                 "--spacing", "1/32", "--f-th", "0", "--alpha", "0", "--max-indent", "0.01", "--step", "1e-3",
                 "-o", str(out), "-q", "--no-plot"]) in (0, 3)
    m.rename(tmp_path / "moved.npy")
    capsys.readouterr()
    assert main(["plot", str(out), "-o", str(tmp_path / "hm.png")]) == 0
    err = capsys.readouterr().err
    assert "its parameter record does not rebuild" in err and "no such file" in err
    assert "which the axes do not say" not in err
    # an SI run's figure then has axes without units: said too (a user's hunt)
    np.save(m, np.zeros((41, 41)))
    si = tmp_path / "si.parquet"
    assert main(["run", "--units", "si", "--youngs-modulus", "1e6", "--poisson-ratio", "0.5", "--shape", "height_map",
                 "--height-map", str(m), "--map-pixel-size", "1e-6", "--spacing", "1e-6", "--f-th", "0",
                 "--max-indent", "1e-8", "--step", "1e-9", "-o", str(si), "-q", "--no-plot"]) in (0, 3)
    m.unlink()
    capsys.readouterr()
    assert main(["plot", str(si), "-o", str(tmp_path / "si.png")]) == 0
    assert "its lengths are in m and its forces in N, which the axes do not say" in capsys.readouterr().err


def test_caption_numbers_are_rounded_before_they_are_written():
    """An SI force of 9.99999999998603e-06 N was captioned "10 × 10⁻⁶ N", 9999.6 was
    "1e+04" and d = -0.0 was "-0" (a user's hunt); P = -0.00346 had a hyphen where
    P = -4.82e-4 had mathtext's minus (another)."""
    cases = {9.99999999998603e-06: "$10^{-5}$", 9999.6: "$10^{4}$", -0.0: "0", 1234.5: "1230",
             2.5e-4: r"$2.5\times10^{-4}$", -1e-5: "$-10^{-5}$", 0.135: "0.135", 0.5: "0.5",
             0.00319: "0.00319", 12.0: "12", -0.00346: "\u22120.00346"}
    assert {x: plots.number(x) for x in cases} == cases


def test_a_run_whose_unloading_was_capped_is_not_drawn_as_a_finished_one(tmp_path, capsys):
    """With max_unload_steps reached, tfm show titled the snapshot of the largest tension
    "(pull-off)", and neither it nor the curve's figure showed that the curve stops short
    (a user's hunt)."""
    from tfm.snapshots import Fields

    out = tmp_path / "cap.parquet"
    assert main(["run", "--spacing", "1/32", "--shape", "paraboloid", "--k-th", "0.02", "--max-indent", "0.05",
                 "--step", "1e-3", "--max-unload-steps", "60", "--snapshots", "events", "-q", "--no-plot",
                 "-o", str(out)]) == 3
    curve = pd.read_parquet(out)
    assert plots.unload_incomplete(curve) and int(curve["n_contact"].iloc[-1]) > 0
    fig = plots.plot_curve(curve, tfm.Params.from_dict(tfm.results.read_metadata(out)["params"]))
    assert plots.INCOMPLETE in fig._suptitle.get_text()
    fields = Fields(tmp_path / "cap.fields.nc")
    snap = fields.snapshot(fields.event_step("pull_off"))
    assert "(largest tension so far" in plots.snapshot_title(snap, None, plots.unload_incomplete(curve))
    capsys.readouterr()
    assert main(["show", str(out), "--step", "pull_off"]) == 0
    assert "cap.parquet is a flagged run: unloading stopped at max_unload_steps" in capsys.readouterr().err
    # a finished run keeps its words
    assert "(pull-off" in plots.snapshot_title(snap, None, plots.unload_incomplete(curve.iloc[:0]))


def test_a_caption_names_the_settings_that_moved_the_numbers():
    """A run with self_term 3 and the single snap rule had the default run's caption, with a
    pull-off 26 % lower (a user's hunt); settings at their default, or that do not apply,
    stay out of it."""
    base = dict(spacing="1/32", k_th=0.02, shape="paraboloid", max_indent=0.05, step=1e-3)
    plain = plots.run_caption(tfm.Params.from_dict(base))
    moved = plots.run_caption(tfm.Params.from_dict(dict(base, self_term=3.0, snap_rule="single")))
    assert moved == plain + ", self_term = 3, snap_rule = single"
    assert "jitter" not in plots.run_caption(tfm.Params.from_dict(dict(base, layout="hexagonal", operator="tree")))
    # a jittered layout's positions are its jitter and seed: named even at their defaults,
    # or two different layouts had the same caption (a user's hunt)
    jittered = dict(base, layout="jittered", operator="tree")
    assert "jittered layout (jitter 0.25, seed 0)" in plots.run_caption(tfm.Params.from_dict(jittered))
    assert "jittered layout (jitter 0.1, seed 7)" in plots.run_caption(
        tfm.Params.from_dict(dict(jittered, jitter=0.1, seed=7)))


def test_a_gif_s_frame_time_is_the_nearest_it_can_store_and_a_rate_it_cannot_is_said(stored_run, tmp_path, capsys):
    """--fps 8 wrote 120 ms frames (int(1000 / fps) cut to whole centiseconds), and 60 and
    100 fps made the same file, without a word (a user's hunt)."""
    from PIL import Image

    for fps, ms, note in ((10, 100, False), (8, 120, True), (45, 20, True)):
        out = tmp_path / f"f{fps}.gif"
        assert main(["animate", str(stored_run), "-o", str(out), "--fps", str(fps)]) == 0
        assert Image.open(out).info["duration"] == ms
        err = capsys.readouterr().err
        assert ("stores frame times in hundredths of a second" in err) == note, err
