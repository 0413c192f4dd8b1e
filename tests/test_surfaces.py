"""Rough surfaces (tfm.surfaces): the generator's statistics, seeds, SurfaceTopography,
height maps, threshold disorder and the early refusal of bad input."""
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from tfm.geometry import heights, make_layout
from tfm.params import ParameterError, Params
from tfm.surfaces import (fourier_synthesis, psd_exponent, radial_psd, sample, self_affine_psd,
                          spectral_rms_slope, wavevectors)
from tfm.threshold import disorder_factors, mean_threshold, threshold_forces, weibull_modulus

N = 512
DX = 1.0 / N


@pytest.mark.parametrize("hurst", [0.3, 0.8])
@pytest.mark.parametrize("target", ["rms_slope", "rms_height"])
def test_psd_exponent_and_rms(hurst, target):
    short, long = 4 * DX, N * DX / 4
    h = fourier_synthesis(N, DX, hurst, short_cutoff=short, long_cutoff=long, seed=7, **{target: 0.3})
    # One realization's log-binned PSD between the cutoffs: over 10 seeds the fitted
    # exponent scatters by +-0.04 around -2-2H; the bound is 0.1.
    slope = psd_exponent(h, DX, 2 * np.pi / long, 2 * np.pi / short)
    assert abs(slope - (-2 - 2 * hurst)) < 0.1
    # each realization is rescaled to the request, so it holds to round-off (the issue
    # asks 2 %; 1e-9 leaves room for the FFT's rounding only)
    got = spectral_rms_slope(h, DX) if target == "rms_slope" else float(np.sqrt(np.mean(h ** 2)))
    assert got == pytest.approx(0.3, rel=1e-9)
    assert abs(h.mean()) < 1e-12


def test_rms_slope_is_spectral_and_finite_differences_are_close():
    h = fourier_synthesis(256, 1 / 256, 0.8, rms_slope=1.0, short_cutoff=8 / 256, seed=3)
    gx = (np.roll(h, -1, 0) - np.roll(h, 1, 0)) * 128
    gy = (np.roll(h, -1, 1) - np.roll(h, 1, 1)) * 128
    fd = math.sqrt(float(np.mean(gx ** 2 + gy ** 2)))
    # central differences of a wave of 8 spacings keep sin(2pi/8)/(2pi/8) = 0.90 of its
    # slope; the PSD-weighted loss over the band is a few per cent, never a gain
    assert 0.9 < fd < 1.0


def test_same_seed_same_surface_bit_for_bit():
    kw = dict(short_cutoff=4 * DX, long_cutoff=0.5, rolloff=0.3)
    a = fourier_synthesis(N, DX, 0.8, rms_height=1.0, seed=11, **kw)
    b = fourier_synthesis(N, DX, 0.8, rms_height=1.0, seed=11, **kw)
    c = fourier_synthesis(N, DX, 0.8, rms_height=1.0, seed=12, **kw)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    # the rms only rescales the surface of a seed
    d = fourier_synthesis(N, DX, 0.8, rms_height=2.0, seed=11, **kw)
    np.testing.assert_allclose(d, 2 * a, rtol=1e-12, atol=1e-12)


def test_psd_shape_follows_cutoffs_and_rolloff():
    q = np.array([1.0, 5.0, 10.0, 20.0, 40.0, 90.0])
    psd = self_affine_psd(q, 0.5, short_cutoff=2 * np.pi / 50, long_cutoff=2 * np.pi / 10, rolloff=0.5)
    assert psd[-1] == 0.0                                  # above q_s
    assert psd[0] == psd[1] == pytest.approx(0.25 * 10.0 ** -3)   # rolloff^2 C(q_L)
    assert psd[3] / psd[4] == pytest.approx(2.0 ** 3)      # q^(-2-2H), H = 0.5


@pytest.mark.parametrize("hurst", [0.3, 0.8])
def test_matches_surface_topography_fourier_synthesis(hurst):
    st = pytest.importorskip("SurfaceTopography.Generation")
    n, L = 256, 1.0
    dx = L / n
    kw = dict(short_cutoff=8 * dx, long_cutoff=L / 4, rolloff=0.5)
    reps = 6
    q = wavevectors(n, dx).ravel()
    edges = np.geomspace(2 * np.pi / L, 2 * np.pi / kw["short_cutoff"], 13)
    which = np.digitize(q, edges) - 1
    keep = (which >= 0) & (which < 12)
    modes = np.bincount(which[keep], minlength=12)

    def binned(h):
        C = (dx ** 2 * np.abs(np.fft.fft2(h - h.mean())) ** 2 / n ** 2).ravel()
        return np.bincount(which[keep], weights=C[keep], minlength=12) / np.maximum(modes, 1)

    ours = np.mean([binned(fourier_synthesis(n, dx, hurst, rms_slope=0.1, seed=s, **kw))
                    for s in range(reps)], axis=0)
    theirs = np.mean([binned(st.fourier_synthesis((n, n), (L, L), hurst, rms_slope=0.1, rng=100 + s,
                                                  **kw).heights()) for s in range(reps)], axis=0)
    ok = modes >= 8
    ratio = ours[ok] / theirs[ok]
    # A bin's mean PSD over m modes (m/2 independent complex coefficients, +-q are
    # conjugate) and `reps` surfaces has relative scatter sqrt(2 / (m reps)); a ratio of
    # two such means sqrt(2) times that. Four standard deviations per bin:
    sigma = np.sqrt(2.0) * np.sqrt(2.0 / (modes[ok] * reps))
    assert np.all(np.abs(np.log(ratio)) < 4 * sigma + 0.02), (ratio, sigma)
    # and the same overall level: tfm fixes each realization's rms slope, SurfaceTopography
    # its expectation; their realized slopes scatter by about 1 %
    assert np.exp(np.mean(np.log(ratio))) == pytest.approx(1.0, abs=0.05)


def test_radial_psd_of_a_single_wave():
    n = 64
    x = np.arange(n) / n
    h = np.sin(2 * np.pi * 4 * x)[:, None] * np.ones(n)[None, :]
    q, C = radial_psd(h, 1 / n)
    # bins are pi/spacing/(n/2) = 2 pi wide; the peak's bin mean lies within one width
    assert abs(q[np.argmax(C)] - 2 * np.pi * 4) <= 2 * np.pi


# ---- the run's surface ---------------------------------------------------------------
ROUGH = dict(spacing=1 / 32, k_th=0.02, shape="paraboloid", max_indent=0.05, step=1e-3,
             rms_height=1e-3, short_cutoff=4 / 32)


def test_rough_shape_adds_roughness_and_apex_stays_at_zero():
    p = Params.from_dict(ROUGH)
    smooth = Params.from_dict({k: v for k, v in ROUGH.items() if k not in ("rms_height", "short_cutoff")})
    lay = make_layout(p)
    x0, x0_smooth = heights(p, lay), heights(smooth, lay)
    assert x0.max() == 0.0
    rough = (x0 - x0_smooth) - np.mean(x0 - x0_smooth)
    assert np.sqrt(np.mean(rough ** 2)) == pytest.approx(1e-3, rel=1e-9)   # square layout: exact
    # a smooth record is unchanged by the new code path (apex exactly 0, no shift)
    assert x0_smooth.max() == 0.0 and x0_smooth[lay.x.size // 2] == 0.0


def test_rough_flat_punch_and_jittered_layout():
    p = Params.from_dict(dict(spacing=1 / 16, f_th=0, shape="flat_punch", radius=0.5, max_indent=0.01,
                              step=1e-3, rms_slope=0.1, layout="jittered", operator="direct"))
    lay = make_layout(p)
    x0 = heights(p, lay)
    inside = np.isfinite(x0)
    assert x0[inside].max() == 0.0 and np.all(np.hypot(lay.x, lay.y)[~inside] > 0.5)


def test_sample_is_exact_on_pixels_and_bilinear_between():
    rng = np.random.default_rng(0)
    h = rng.normal(size=(9, 7))
    xs = (np.arange(9) - 4) * 0.1
    ys = (np.arange(7) - 3) * 0.1
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    np.testing.assert_array_equal(sample(h, 0.1, X.ravel(), Y.ravel()), h.ravel())
    plane = 2.0 * X - 3.0 * Y + 1.0
    pts = rng.uniform(-0.3, 0.3, size=(2, 50))
    np.testing.assert_allclose(sample(plane, 0.1, pts[0], pts[1]), 2 * pts[0] - 3 * pts[1] + 1, rtol=1e-12)


# ---- height maps -----------------------------------------------------------------------
def _map(tmp_path, name="m.npy", n=41, seed=0, array=None):
    path = tmp_path / name
    if array is None:
        array = fourier_synthesis(n, 1 / 32, 0.8, rms_height=1e-3, seed=seed)
    np.save(path, array)
    return str(path)


def test_height_map_run_id_follows_content_not_path(tmp_path):
    a = _map(tmp_path, "a.npy")
    b = _map(tmp_path, "b.npy")                 # same heights, other file
    c = _map(tmp_path, "c.npy", seed=1)
    kw = dict(shape="height_map", spacing=1 / 32, f_th=0.0, max_indent=1e-3, step=1e-4)
    pa, pb, pc = (Params(height_map=m, **kw) for m in (a, b, c))
    assert pa.height_map_hash == pb.height_map_hash != pc.height_map_hash
    assert pa.run_id == pb.run_id != pc.run_id
    # rebuilt from its own record (a table row), the same run; after the file changed, refused
    assert Params.from_dict(pa.to_dict()).run_id == pa.run_id
    np.save(a, np.zeros((41, 41)))
    with pytest.raises(ParameterError, match="height_map: the content .* changed"):
        Params.from_dict(pa.to_dict())
    assert pa.replace(height_map=c).height_map_hash == pc.height_map_hash


def test_a_map_changed_after_its_run_was_made_is_refused_when_the_run_starts(tmp_path):
    """A campaign validates its records first and runs them later: a map file changed in
    between ran with the new heights and was stored under the old content's run id (its
    height_map_hash), so the table held a wrong row for good. The run now fails, named."""
    from tfm import simulate
    from tfm.campaign import load_failures, load_tables, run_campaign, spec_from_dict

    a, b = _map(tmp_path, "a.npy"), _map(tmp_path, "b.npy", seed=1)
    kw = dict(shape="height_map", spacing="1/32", map_pixel_size="1/32", f_th=0.0, max_indent=1e-3, step=1e-4)
    p = Params.from_dict(dict(kw, height_map=a))
    np.save(a, np.load(b))
    with pytest.raises(ValueError, match="a.npy has changed since the run was made"):
        simulate(p)
    _map(tmp_path, "c.npy", seed=2)
    spec = spec_from_dict({"name": "maps", "base": kw, "sweep": {"height_map": [b, str(tmp_path / "c.npy")]}})
    np.save(tmp_path / "c.npy", np.load(b))                 # changed after validation
    root = run_campaign(spec, results_dir=tmp_path / "res", quiet=True)
    summary, _ = load_tables(root)
    assert summary["p_height_map"].tolist() == [b]
    assert "c.npy has changed since the run was made" in load_failures(root)["error"].iloc[0]


def test_height_map_record_is_usable_from_any_folder(tmp_path, monkeypatch):
    """A map given by a relative path is stored as an absolute one: the record rebuilds
    (and finds its map) from another working directory, with the same run id."""
    _map(tmp_path, "rel.npy")
    monkeypatch.chdir(tmp_path)
    p = Params(shape="height_map", height_map="rel.npy", spacing=1 / 32, f_th=0.0, max_indent=1e-3, step=1e-4)
    assert p.height_map == str(tmp_path / "rel.npy")
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert Params.from_dict(p.to_dict()).run_id == p.run_id


def test_height_map_lands_on_springs_and_interpolates(tmp_path):
    arr = np.random.default_rng(1).normal(size=(21, 21)) * 1e-3
    m = _map(tmp_path, array=arr)
    p = Params(shape="height_map", height_map=m, spacing=1 / 32, f_th=0, max_indent=1e-3, step=1e-4,
               map_pixel_size=1 / 32)
    assert p.half_width == pytest.approx(10 / 32)
    x0 = heights(p, make_layout(p))
    np.testing.assert_allclose(x0, arr.ravel() - arr.max(), rtol=0, atol=1e-15)
    # a map of a plane with a finer pixel: bilinear interpolation is exact for planes
    xs = (np.arange(81) - 40) / 128
    plane = 0.01 * xs[:, None] + 0.02 * xs[None, :]
    q = Params(shape="height_map", height_map=_map(tmp_path, "plane.npy", array=plane), spacing=1 / 32,
               f_th=0, max_indent=1e-3, step=1e-4, map_pixel_size=1 / 128)
    lay = make_layout(q)
    expect = 0.01 * lay.x + 0.02 * lay.y
    np.testing.assert_allclose(heights(q, lay), expect - expect.max(), atol=1e-15)


def test_a_npy_map_without_a_pixel_size_is_warned_about(tmp_path):
    """A .npy map's pixel defaults to the spacing, so a spacing study of one map compared
    bodies of different sizes (a paraboloid map gave R = 1 at 1/64 and R = 4 at 1/32),
    without a word."""
    from tfm.params import ParameterWarning

    kw = dict(shape="height_map", height_map=_map(tmp_path), spacing="1/32", f_th=0.0, max_indent=1e-3,
              step=1e-4)
    with pytest.warns(ParameterWarning, match=r"map_pixel_size: not given, and the map carries none \(a \.npy file\)"):
        Params.from_dict(kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Params.from_dict({**kw, "map_pixel_size": "1/32"})
    # a text matrix was called "a .npy array" too
    np.savetxt(tmp_path / "m.txt", np.load(kw["height_map"]))
    with pytest.warns(ParameterWarning, match=r"carries none \(a \.txt file\)"):
        Params.from_dict({**kw, "height_map": str(tmp_path / "m.txt")})


def test_a_npy_map_without_a_pixel_size_is_warned_about_on_every_path_to_a_run(tmp_path):
    """The warning came only from Params.from_dict of a partial record: simulate of a
    Params(...), of a record with a new spacing (another body, without a word), or of a
    complete record with overrides said nothing. Checked without running: simulate
    refuses the bad progress argument after the parameters, before any computation."""
    from tfm import ParameterWarning, simulate

    kw = dict(shape="height_map", height_map=_map(tmp_path), spacing=1 / 32, f_th=0.0, max_indent=1e-3,
              step=1e-4)
    p = Params(**kw)
    stored = Params.from_dict(kw, advise=False).to_dict()
    for args, over in (((p,), {}), ((Params(**kw),), {"spacing": 1 / 16}), ((stored,), {"spacing": 1 / 16}),
                       ((), kw)):
        with pytest.warns(ParameterWarning, match="map_pixel_size: not given") as caught, \
                pytest.raises(ParameterError, match="progress"):
            simulate(*args, **over, progress=5)
        assert caught[0].filename == __file__          # points at the caller, not into tfm
    with warnings.catch_warnings():                    # once per record, and not for a stored one
        warnings.simplefilter("error")
        for args in ((p,), (stored,)):
            with pytest.raises(ParameterError, match="progress"):
                simulate(*args, progress=5)


def test_contact_at_a_cropped_side_of_a_height_map_is_flagged(tmp_path, capsys):
    """A map is a finite body: contact at its own edge is physical. But a grid cut short
    of the map, by extent or as the centred square of an oblong map, was never flagged:
    a paraboloid map cut to extent 0.15 under a 0.2-wide contact gave a 4 % lower force
    and exit 0, where the same cut paraboloid is flagged. Now contact at a cut side is,
    and at the map's own edge still is not; an oblong map's unused pixels are noted."""
    from tfm import simulate
    from tfm.cli import main

    xs = (np.arange(65) - 32) / 64
    bowl = -(xs[:, None] ** 2 + xs[None, :] ** 2) / 2.0          # the paraboloid R = 1, +-0.5
    kw = dict(shape="height_map", spacing=1 / 32, f_th=0.0, max_indent=0.05, step=1e-3, map_pixel_size=1 / 64)
    # the advice fits a map (extent_margin does not apply to one: it said "raise extent_margin")
    with pytest.warns(UserWarning, match="grid edge.*enlarge extent, if the map covers it, or use a larger map"):
        cut = simulate(height_map=_map(tmp_path, "bowl.npy", array=bowl), extent=0.15, **kw)
    with pytest.warns(UserWarning, match="grid edge.*use a larger map or a shallower max_indent"):
        simulate(height_map=_map(tmp_path, "wide.npy", array=bowl[16:49, :]), **dict(kw, max_indent=0.1))
    assert cut.summary["contact_reached_edge"]
    whole = simulate(height_map=_map(tmp_path, "small.npy", array=bowl[16:49, 16:49]), **kw)
    assert whole.summary["max_contact_radius"] > 0.2 and not whole.summary["contact_reached_edge"]
    strip = _map(tmp_path, "strip.npy", array=bowl[16:49, :])     # +-0.25 along x, +-0.5 along y
    out = tmp_path / "strip.parquet"
    assert main(["run", "--shape", "height_map", "--height-map", strip, "--map-pixel-size", "1/64",
                 "--spacing", "1/32", "--f-th", "0", "--max-indent", "0.05", "--step", "1e-3", "-o", str(out),
                 "--no-plot"]) == 0                       # its contact stays off the cut sides
    assert "reaches ±0.25 along x and ±0.5 along y, and its pixels beyond the square are not used" in \
        capsys.readouterr().err
    # a square map with an even pixel count leaves under a spacing unused: no note (there was)
    even = _map(tmp_path, "even.npy", array=bowl[:64, :64])
    assert main(["run", "--shape", "height_map", "--height-map", even, "--map-pixel-size", "1/64",
                 "--spacing", "1/32", "--f-th", "0", "--max-indent", "0.05", "--step", "1e-3",
                 "-o", str(tmp_path / "even.parquet"), "--no-plot"]) == 0
    assert "not used" not in capsys.readouterr().err


def test_the_row_an_even_height_map_leaves_over_is_noted_not_flagged(tmp_path, capsys):
    """A 64 x 64 map at its own pixel size: the centred grid leaves its last pixel along
    each axis unused, and contact next to it was flagged as a too-small grid ("raise
    extent_margin or give a larger extent", both refused for a map), exit 3. Now it is
    noted before the run; a 63 x 63 map leaves nothing over."""
    from tfm.cli import main

    for n, note in ((64, True), (63, False)):
        flat = _map(tmp_path, f"flat{n}.npy", array=np.zeros((n, n)))
        assert main(["run", "--shape", "height_map", "--height-map", flat, "--map-pixel-size", "1/32",
                     "--spacing", "1/32", "--f-th", "0", "--max-indent", "0.01", "--step", "1e-3",
                     "-o", str(tmp_path / f"flat{n}.parquet"), "--no-plot"]) == 0
        err = capsys.readouterr().err
        assert "grid edge" not in err
        assert ("64 x 64 pixels, an even count: the grid, centred on pixel (31, 31), leaves the map's last "
                "pixel along x and y unused" in err) == note


@pytest.mark.parametrize("array, match", [
    (np.zeros((5, 5, 2)), "2-D"),
    (np.full((41, 41), np.nan), "NaN"),
    (np.zeros((9, 9)), "smaller than the grid"),
])
def test_bad_height_maps_are_refused(tmp_path, array, match):
    m = _map(tmp_path, array=array)
    with pytest.raises(ParameterError, match=match):
        Params(shape="height_map", height_map=m, spacing=1 / 32, f_th=0, max_indent=1e-3, step=1e-4,
               extent=0.5)


@pytest.mark.parametrize("cut", [0, 60], ids=["empty", "truncated"])
def test_unreadable_npy_maps_are_refused(tmp_path, cut):
    # an empty file raised EOFError from np.load, which escaped as a traceback
    whole = _map(tmp_path, "whole.npy")
    broken = tmp_path / "broken.npy"
    broken.write_bytes(Path(whole).read_bytes()[:cut])
    with pytest.raises(ParameterError, match=r"height_map: cannot read .*broken\.npy' as a \.npy array"):
        Params(shape="height_map", height_map=str(broken), f_th=0, max_indent=1e-3, step=1e-4)


def test_a_text_file_named_npy_is_not_called_pickled_data(tmp_path):
    text = tmp_path / "heights.npy"
    text.write_text("0.0 0.1\n0.2 0.3\n")
    with pytest.raises(ParameterError, match="as a .npy array: it has no NumPy header") as info:
        Params(shape="height_map", height_map=str(text), f_th=0, max_indent=1e-3, step=1e-4)
    assert "pickled" not in str(info.value)


def test_missing_map_and_map_without_shape(tmp_path):
    with pytest.raises(ParameterError, match="height_map: no such file"):
        Params(shape="height_map", height_map=str(tmp_path / "nope.npy"), f_th=0, max_indent=1e-3, step=1e-4)
    # an array's repr came back as "no such file '[[ 1.257e-04 ...'"; '' and a folder as
    # "file . not found" and "file /tmp not found"
    for value, match in ((np.zeros((3, 3)), "height_map: expected the path of a map file .*got a ndarray; "
                                            "save an array with numpy.save"),
                         ("", "height_map: expected the path of a map file .*got ''"),
                         (str(tmp_path), "is a folder, not a map file")):
        with pytest.raises(ParameterError, match=match):
            Params(shape="height_map", height_map=value, f_th=0, max_indent=1e-3, step=1e-4)
    with pytest.raises(ParameterError, match="height_map: shape='height_map' needs"):
        Params(shape="height_map", f_th=0, max_indent=1e-3, step=1e-4)
    with pytest.raises(ParameterError, match="height_map: applies only to shape='height_map'"):
        Params(height_map=_map(tmp_path))
    with pytest.raises(ParameterError, match="max_indent: 'auto'"):
        Params(shape="height_map", height_map=_map(tmp_path), f_th=0)


# ---- bad roughness input ---------------------------------------------------------------
@pytest.mark.parametrize("changes, match", [
    (dict(hurst=0.0), r"hurst: must be in \(0, 1\)"),
    (dict(hurst=1.0), r"hurst: must be in \(0, 1\)"),
    (dict(short_cutoff=1.5 / 32), "short_cutoff: must be >= 2 spacings"),
    (dict(short_cutoff=0.3, long_cutoff=0.2), "short_cutoff: must be < long_cutoff"),
    (dict(rms_height=-1e-3), "rms_height: must be >= 0"),
    (dict(rms_height=0.0, rms_slope=-0.1), "rms_slope: must be >= 0"),
    (dict(rms_slope=0.1), "rms_slope / rms_height: give one"),
    (dict(rolloff=-1.0), "rolloff: must be >= 0"),
    (dict(long_cutoff=5.0), "long_cutoff: must be <= the grid side"),
    (dict(max_indent="auto"), "max_indent: 'auto' assumes a smooth body"),
])
def test_bad_roughness_fails_early(changes, match):
    with pytest.raises(ParameterError, match=match):
        Params.from_dict({**ROUGH, **changes})


def test_roughness_parameters_need_roughness(tmp_path):
    with pytest.raises(ParameterError, match="roughness_seed: 3 has no effect .* the surface is rough"):
        Params(roughness_seed=3)
    with pytest.raises(ParameterError, match="disorder_width: 0.1 has no effect .* threshold_disorder is"):
        Params(disorder_width=0.1)
    with pytest.raises(ParameterError, match="radius: 2.0 has no effect .* shape is 'sphere'"):
        Params(shape="height_map", height_map=_map(tmp_path), radius=2.0, f_th=0.0, max_indent=1e-3, step=1e-4)


# ---- threshold disorder ----------------------------------------------------------------
@pytest.mark.parametrize("kind, width", [("uniform", 0.3), ("weibull", 0.3), ("weibull", 1.0)])
def test_disorder_mean_one_and_requested_spread(kind, width):
    xi = disorder_factors(kind, width, seed=5, n=200_000)
    # 2e5 samples: the sample mean and std scatter by ~width/450 and ~width/300; 1 % of
    # the mean and 3 % of the width is over 4 standard errors
    assert xi.mean() == pytest.approx(1.0, abs=0.01)
    assert xi.std() == pytest.approx(width, rel=0.03)
    assert xi.min() >= 0.0
    np.testing.assert_array_equal(xi, disorder_factors(kind, width, seed=5, n=200_000))


def test_weibull_modulus_inverts_the_coefficient_of_variation():
    for m in (0.8, 1.0, 3.0, 10.0):
        cv = math.sqrt(math.gamma(1 + 2 / m) / math.gamma(1 + 1 / m) ** 2 - 1)
        assert weibull_modulus(cv) == pytest.approx(m, rel=1e-8)


def test_threshold_forces_carry_the_disorder():
    p = Params(spacing=1 / 16, f_th=2e-4, threshold_disorder="uniform", disorder_width=0.2, disorder_seed=1)
    lay = make_layout(p)
    f = threshold_forces(p, lay.area)
    assert mean_threshold(p) == 2e-4
    np.testing.assert_allclose(f, 2e-4 * disorder_factors("uniform", 0.2, 1, lay.n))
    with pytest.raises(ParameterError, match=r"disorder_width: must be in \(0, 0.5774\]"):
        Params(f_th=2e-4, threshold_disorder="uniform", disorder_width=0.7)
    with pytest.raises(ParameterError, match="threshold_disorder: unknown value"):
        Params(threshold_disorder="gauss", disorder_width=0.1)
    # no width given: said so ("must be in [0.015, 2] ... got 0.0" read as a bad zero)
    with pytest.raises(ParameterError, match=r"disorder_width: must be > 0 with threshold_disorder='weibull' .*it is 0 \(also its default when not given\)"):
        Params(f_th=2e-4, threshold_disorder="weibull")
    assert Params.from_dict({"threshold_disorder": None}).threshold_disorder == "none"


# ---- ensembles over seeds ----------------------------------------------------------------
def _shoelace(x, y):
    """Signed area of the closed polygon (x, y), counter-clockwise positive."""
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_hysteresis_is_the_loop_area():
    import pandas as pd
    from tfm.analysis import hysteresis
    # load along P = d^2 to d = 1, unload along P = d^3 - 0.1 sin(pi d) past zero force
    up = np.linspace(0, 1, 201)[1:]
    down = np.linspace(1, -0.2, 241)[1:]
    indent = np.concatenate([up, down])
    force = np.concatenate([up ** 2, down ** 3 - 0.1 * np.sin(np.pi * down)])
    force[-1] = 0.0
    curve = pd.DataFrame({"indent": indent, "force": force})
    path_x, path_y = np.concatenate([[0.0], indent]), np.concatenate([[0.0], force])
    # the polygon closes along P = 0, which adds nothing to the integral of P d(delta);
    # the path runs clockwise in (delta, P), so its signed area is minus the dissipation
    assert hysteresis(curve) == pytest.approx(-_shoelace(path_x, path_y), rel=1e-12)


def test_ensemble_stats_mean_and_spread_over_seeds():
    import pandas as pd
    from tfm.analysis import ensemble_stats
    rows, curves = [], []
    for rms in (1e-3, 2e-3):
        for seed, po in enumerate((0.01, 0.012, 0.014)):
            rid = f"{rms}-{seed}"
            rows.append({"run_id": rid, "p_rms_height": rms, "p_roughness_seed": seed, "p_alpha": 0.75})
            curves.append(pd.DataFrame({"run_id": rid, "indent": [0.1, 0.2, 0.1, 0.0],
                                        "force": [1.0, 2.0, 0.0, -po * rms * 1000],
                                        "contact_area": [0.1, 0.3, 0.2, 0.05]}))
    stats = ensemble_stats(pd.DataFrame(rows), pd.concat(curves))
    assert list(stats.columns[:2]) == ["p_rms_height", "n"]       # seeds and constants are not groups
    r = stats.iloc[1]
    assert r["n"] == 3
    assert r["pull_off_force_mean"] == pytest.approx(0.024)
    assert r["pull_off_force_std"] == pytest.approx(0.004)       # sample std, ddof = 1
    assert r["area_at_max_load_mean"] == pytest.approx(0.3) and r["area_at_max_load_std"] == 0.0
    # the jittered layout's seed is a seed too: grouped by it, each group had n = 1
    jittered = pd.DataFrame(rows).rename(columns={"p_roughness_seed": "p_seed"})
    assert ensemble_stats(jittered, pd.concat(curves))["n"].tolist() == [3, 3]
    # one column as a string: `by` was split into characters (KeyError 'p'), and `seeds`
    # became a grouping column, every group n = 1 and every std NaN
    one = ensemble_stats(pd.DataFrame(rows), pd.concat(curves), by="p_rms_height", seeds="p_roughness_seed")
    pd.testing.assert_frame_equal(one, stats)
    with pytest.raises(ValueError, match="ensemble_stats: seeds: no column 'p_roughnes_seed' in the table"):
        ensemble_stats(pd.DataFrame(rows), pd.concat(curves), seeds=["p_roughnes_seed"])
    with pytest.raises(ValueError, match="ensemble_stats: by: no column 'p_rms'"):
        ensemble_stats(pd.DataFrame(rows), pd.concat(curves), by="p_rms")
    # a parameter set in some runs and unset (NaN) in others is a grouping column: under
    # pandas 3 astype(str) kept NaN missing, so {NaN, 1.0} counted as one value and the
    # two settings became one ensemble of 6 (a user's hunt)
    mixed = pd.DataFrame(rows).assign(p_extent=[np.nan if r["p_rms_height"] == 1e-3 else 1.0 for r in rows])
    split = ensemble_stats(mixed, pd.concat(curves))
    assert list(split.columns[:3]) == ["p_rms_height", "p_extent", "n"] and split["n"].tolist() == [3, 3]


def test_rough_campaign_files_expand():
    from tfm.campaign.spec import load_spec
    sphere = load_spec("campaigns/rough_sphere.toml")
    punch = load_spec("campaigns/rough_punch_area_load.toml")
    assert len(sphere.runs) == 15 and len(punch.runs) == 6
    assert {r.params.roughness_seed for r in sphere.runs} == {0, 1, 2}


def test_rough_run_with_disorder_end_to_end():
    import tfm
    p = Params.from_dict(dict(ROUGH, threshold_disorder="weibull", disorder_width=0.3, max_indent=0.02,
                              step=2e-3))
    res = tfm.simulate(p)
    assert res.summary["unload_complete"] and res.summary["pull_off_force"] > 0
    assert res.curve["indent"].iloc[0] > 0 and res.curve["n_contact"].iloc[0] >= 1


def test_surface_topography_file_in_si_units(tmp_path):
    """A map in a SurfaceTopography format (here NetCDF in micrometres) comes in with its
    own pixel size and unit, converted to metres."""
    st = pytest.importorskip("SurfaceTopography")
    arr = np.random.default_rng(2).normal(size=(40, 40))                 # micrometres
    st.Topography(arr, (40.0, 40.0), unit="um").to_netcdf(str(tmp_path / "t.nc"))
    p = Params(units="si", youngs_modulus=1e6, poisson_ratio=0.5, f_th=0.0, shape="height_map",
               height_map=str(tmp_path / "t.nc"), spacing=1e-6, max_indent=1e-7, step=1e-8)
    lay = make_layout(p)
    assert lay.shape == (39, 39)          # centre pixel 19, 19 pixels on its short side
    x0 = heights(p, lay)
    # the file stores its sizes in single precision, read back as the decimals written
    # (_stored_decimal): the springs sit on the pixels, and the heights are the file's
    # times 1e-6 (atol: the subtraction of the maximum rounds at 1e-22 m; 1e-12 is loose)
    expect = arr[0:39, 0:39].ravel() * 1e-6
    np.testing.assert_allclose(x0, expect - expect.max(), rtol=0, atol=1e-12)


def test_a_single_precision_size_in_a_file_keeps_the_whole_grid(tmp_path):
    """65 x 65 pixels of 1 mm in a NetCDF file: its size came back as 0.064999998 m, the
    pixel 4e-8 short of the 1 mm spacing, and the grid had 63 springs a side where the same
    heights in a .npy with map_pixel_size 1e-3 have 65, with no note and no edge flag."""
    st = pytest.importorskip("SurfaceTopography")
    arr = np.random.default_rng(3).normal(size=(65, 65)) * 1e-6
    st.Topography(arr, (65e-3, 65e-3), unit="m").to_netcdf(str(tmp_path / "m.nc"))
    np.save(tmp_path / "m.npy", arr)
    common = dict(units="si", youngs_modulus=1e6, poisson_ratio=0.5, f_th=0.0, shape="height_map",
                  spacing=1e-3, max_indent=1e-6, step=1e-7)
    from_file = Params(height_map=str(tmp_path / "m.nc"), **common)
    from_npy = Params(height_map=str(tmp_path / "m.npy"), map_pixel_size=1e-3, **common)
    assert make_layout(from_file).shape == make_layout(from_npy).shape == (65, 65)
    np.testing.assert_array_equal(heights(from_file, make_layout(from_file)),
                                  heights(from_npy, make_layout(from_npy)))


def test_text_maps_are_read_as_heights_and_unknown_formats_named_briefly(tmp_path):
    """A numpy.savetxt matrix failed with "physical_sizes could not be extracted from
    file, you must provide it" though map_pixel_size was given; it is read as a .npy is.
    A .csv dumped SurfaceTopography's 48 lines of readers tried."""
    pytest.importorskip("SurfaceTopography")
    heights_ = np.random.default_rng(4).random((33, 33)) * 1e-3
    # SurfaceTopography reads a text file's rows along y, as an image: heights[x, y] = row y
    np.save(tmp_path / "m.npy", heights_.T)
    np.savetxt(tmp_path / "m.txt", heights_)
    kw = dict(shape="height_map", map_pixel_size=1 / 32, spacing=1 / 16, f_th=0.0, max_indent=2e-3, step=1e-4)
    p_txt = Params(height_map=str(tmp_path / "m.txt"), **kw)
    p_npy = Params(height_map=str(tmp_path / "m.npy"), **kw)
    np.testing.assert_array_equal(heights(p_txt, make_layout(p_txt)), heights(p_npy, make_layout(p_npy)))
    np.savetxt(tmp_path / "m.csv", heights_, delimiter=",")
    with pytest.raises(ParameterError) as info:
        Params(height_map=str(tmp_path / "m.csv"), **kw)
    assert "cannot tell the format" in str(info.value) and "numpy.savetxt" in str(info.value)
    assert "\n" not in str(info.value)


def test_a_topography_without_a_unit_is_read_in_metres_with_a_warning(tmp_path):
    """Sizes without a unit were taken in metres in silence."""
    from tfm.surfaces import MapUnitWarning

    st = pytest.importorskip("SurfaceTopography")
    path = str(tmp_path / "nounit.nc")
    st.Topography(np.random.default_rng(1).random((33, 33)) * 1e-3, (1.0, 1.0)).to_netcdf(path)
    with pytest.warns(MapUnitWarning, match="gives its size .* but no length unit; .* taken in metres"):
        Params(shape="height_map", height_map=path, spacing=1 / 16, f_th=0.0, max_indent=2e-3, step=1e-4)


def test_a_map_refused_for_its_size_still_says_it_was_read_in_metres(tmp_path, capsys):
    """A 129 x 129 map with sizes but no unit, read as 129 m wide: the command line said only
    "extent/spacing: the grid would have 64000001 springs a side (shrink extent ...)",
    naming an extent never given, and dropped the warning that explains the size."""
    from tfm.cli import main

    st = pytest.importorskip("SurfaceTopography")
    path = str(tmp_path / "nounit.nc")
    st.Topography(np.random.default_rng(1).random((129, 129)) * 1e-6, (129.0, 129.0)).to_netcdf(path)
    assert main(["run", "--shape", "height_map", "--height-map", path, "--spacing", "2e-6", "--f-th", "0",
                 "--max-indent", "1e-7", "--step", "5e-9", "-q", "--no-plot", "-o", str(tmp_path / "c.parquet")]) == 2
    err = capsys.readouterr().err
    assert "tfm: warning:" in err and "no length unit" in err and "taken in metres" in err
    assert "height_map/spacing: the map, read as 128 wide," in err and "pixel size and length unit" in err
    assert err.index("no length unit") < err.index("tfm: error:")


def test_a_steep_surface_is_flagged_before_the_run(tmp_path):
    """A map whose heights and pixel are in different units (rms slope 128 here) ran with
    no word about slopes; the half-space model assumes gentle ones."""
    from tfm import guards, simulate

    steep = _map(tmp_path, "steep.npy", array=np.random.default_rng(0).standard_normal((65, 65)))
    kw = dict(shape="height_map", map_pixel_size=1 / 64, spacing=1 / 32, f_th=0.0, max_indent=0.01, step=5e-4)
    slope = guards.surface_rms_slope(Params(height_map=steep, **kw))
    assert slope > 100
    with pytest.warns(UserWarning, match=r"height_map: the map's rms slope is 1\d\d, steeper than 1 .* same length unit"):
        res = simulate(height_map=steep, **kw)
    assert "rms slope" in res.summary["warnings"]
    gentle = _map(tmp_path, "gentle.npy", array=1e-3 * np.random.default_rng(0).standard_normal((65, 65)))
    assert guards.surface_rms_slope(Params(height_map=gentle, **kw)) == pytest.approx(slope * 1e-3)
    assert not any("rms slope" in n for n in guards.check(Params(height_map=gentle, **kw)))
    assert any("rms_slope: the requested rms slope is 2" in n
               for n in guards.check(Params.from_dict(dict(shape="paraboloid", k_th=0.02, spacing=1 / 32, max_indent=0.05,
                                                          step=1e-3, rms_slope=2.0))))


def test_a_paraboloid_pressed_deeper_than_its_radius_is_flagged():
    """An SI run given the paper's max_indent 0.05 for a 1 mm paraboloid (50 R deep, an
    11 GiB run) started with no word; a sphere that deep is refused by its geometry."""
    from tfm import guards

    si = dict(units="si", youngs_modulus=1e6, poisson_ratio=0.5, work_of_adhesion=0.05, shape="paraboloid",
              radius=1e-3, spacing=2e-5, step=1e-3)
    notes = guards.check(Params.from_dict(dict(si, max_indent=0.05)), memory=False)
    assert any(n.startswith("max_indent: 0.05 m is deeper than the paraboloid's radius 0.001 m: its slope at the "
                            "Hertz contact edge, sqrt(max_indent/R) = 7.07") and "paper-unit values" in n
               for n in notes), notes
    # the slope of the edge is sqrt(max_indent / R): at R deep it is 1, not flagged
    paper = dict(shape="paraboloid", f_th=0.0, radius=0.1, spacing=1 / 64, step=1e-3)
    assert not any(n.startswith("max_indent") for n in guards.check(Params.from_dict(dict(paper, max_indent=0.1)),
                                                                    memory=False))
    assert any(n.startswith("max_indent: 0.2 is deeper than the paraboloid's radius 0.1: its slope") and
               "paper-unit" not in n for n in guards.check(Params.from_dict(dict(paper, max_indent=0.2)), memory=False))


def test_a_steep_surface_given_by_its_rms_height_is_flagged(tmp_path):
    """The steepness flag read rms_slope only: an rms_height of 0.1 at 1/32 (spectral rms
    slope 1.5) ran with no word, and so did roughness added to a height map. The slope is
    the realization's own, as spectral_rms_slope measures it on the synthesized grid."""
    from tfm import guards
    from tfm.surfaces import fourier_synthesis, grid_side, spectral_rms_slope

    kw = dict(shape="paraboloid", f_th=0.0, spacing=1 / 32, extent=0.5, max_indent=0.05, step=1e-3)
    p = Params.from_dict(dict(kw, rms_height=0.1))
    h = fourier_synthesis(grid_side(p), p.spacing, p.hurst, rms_height=0.1, seed=0)
    expected = spectral_rms_slope(h, p.spacing)
    assert expected > 1.0
    assert guards.surface_rms_slope(p) == pytest.approx(expected, rel=1e-12)     # the same surface
    assert any(n.startswith(f"rms_height: the 0.1 rms height surface's rms slope is {expected:.3g}, steeper")
               for n in guards.check(p, memory=False))
    # scaled down tenfold: the same surface, a tenth of the slope, no flag
    assert not any("rms slope" in n for n in guards.check(p.replace(rms_height=0.01), memory=False))
    # heights whose squares overflow: the slope was NaN, which passed the check, with
    # NumPy's overflow warnings; it is now measured (1e301: the 0.1 surface's times 1e301)
    # and flagged, without them
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        notes = guards.check(p.replace(rms_height=1e300), memory=False)
    huge = f"rms_height: the 1e+300 rms height surface's rms slope is {expected * 1e301:.3g}, steeper"
    assert any(n.startswith(huge) for n in notes), notes
    # a flat map with roughness on top: the roughness' slope counts
    flat = _map(tmp_path, "flat.npy", array=np.zeros((65, 65)))
    mk = dict(shape="height_map", height_map=flat, map_pixel_size=1 / 64, spacing=1 / 64, f_th=0.0,
              max_indent=0.05, step=1e-3)
    assert any(n.startswith("height_map and roughness: their combined rms slope is 3, steeper")
               for n in guards.check(Params.from_dict(dict(mk, rms_slope=3.0)), memory=False))


def _topography(tmp_path, name, heights, size, unit):
    st = pytest.importorskip("SurfaceTopography")
    path = str(tmp_path / name)
    st.Topography(heights, size, unit=unit).to_netcdf(path)
    return path


SI_MAP = dict(units="si", youngs_modulus=1e6, poisson_ratio=0.5, f_th=0.0, shape="height_map")


def test_missing_pixels_of_a_topography_are_refused_not_read_as_heights(tmp_path):
    """A masked pixel came in as its fill value, 1e20 um: one pillar, a run with exit 3
    and a warning about the spacing (a user's hunt)."""
    arr = np.random.default_rng(3).normal(size=(33, 33))
    arr[4, 5] = np.nan
    path = _topography(tmp_path, "masked.nc", np.ma.masked_invalid(arr), (33.0, 33.0), "um")
    with pytest.raises(ParameterError, match=r"height_map: 1 heights are NaN .*pixel \[4, 5\]"):
        Params(**SI_MAP, height_map=path, spacing=1e-6, max_indent=1e-6, step=1e-7)


@pytest.mark.parametrize("unit, metres", [("A", 1e-10), ("km", 1e3), ("fm", 1e-15)])
def test_every_length_unit_of_surface_topography_is_read(tmp_path, unit, metres):
    """Files in Å (SurfaceTopography writes "A" as "Å") or km stopped the run with a
    traceback."""
    arr = np.random.default_rng(4).normal(size=(20, 20))
    path = _topography(tmp_path, f"u_{unit}.nc", arr, (20.0, 20.0), unit)
    p = Params(**SI_MAP, height_map=path, spacing=metres, max_indent=metres / 10, step=metres / 100)
    x0 = heights(p, make_layout(p))
    expect = arr[0:19, 0:19].ravel() * metres
    np.testing.assert_allclose(x0, expect - expect.max(), rtol=0, atol=1e-6 * metres)   # sizes in float32


def test_an_unknown_unit_is_refused_when_the_record_is_made(tmp_path, monkeypatch):
    from tfm import surfaces

    path = _topography(tmp_path, "v.nc", np.zeros((8, 8)), (8.0, 8.0), "pm")
    monkeypatch.delitem(surfaces._SI_UNITS, "pm")        # as a unit tfm would not know
    with pytest.raises(ParameterError, match="height_map: unknown length unit 'pm'"):
        Params(**SI_MAP, height_map=path, spacing=1e-6, max_indent=1e-7, step=1e-8)


def test_a_pixel_size_over_a_files_own_is_refused(tmp_path):
    """In paper units a nm file's heights became 1e-9 L* while map_pixel_size set its pixel
    to 1/32 L*: a flat body, every spring in contact, exit 0 (a user's hunt)."""
    arr = np.random.default_rng(5).normal(size=(65, 65)) * 5
    path = _topography(tmp_path, "nm.nc", arr, (650.0, 650.0), "nm")
    with pytest.raises(ParameterError, match="map_pixel_size: .* gives its own pixel size, 10 nm = 1e-08 m"):
        Params(f_th=0.0, shape="height_map", height_map=path, spacing=1 / 32, map_pixel_size=1 / 32,
               max_indent=0.01, step=1e-3)
    # without it, the message says how the file's pixel was taken
    with pytest.raises(ParameterError, match=r"the file's 10 nm converted to metres \(L\* = 1 m in paper units\)"):
        Params(f_th=0.0, shape="height_map", height_map=path, spacing=1 / 32, max_indent=0.01, step=1e-3)
    # the file's own value given again is accepted and gives the same heights
    p = Params(**SI_MAP, height_map=path, spacing=1e-8, map_pixel_size=1e-8, max_indent=1e-8, step=1e-9)
    q = Params(**SI_MAP, height_map=path, spacing=1e-8, max_indent=1e-8, step=1e-9)
    np.testing.assert_allclose(heights(p, make_layout(p)), heights(q, make_layout(q)), rtol=0, atol=1e-15)


def test_a_map_too_small_for_one_spring_is_the_maps_fault(tmp_path):
    """It said "spacing: must be <= the grid half-width (0)"."""
    np.save(tmp_path / "thin.npy", np.zeros((2, 65)))
    with pytest.raises(ParameterError, match=r"height_map: the map \(2 x 65 pixels\) has fewer than 3 pixels "
                                             r"along x: .* needs at least 3 x 3 pixels \(use a larger map\)$"):
        Params(shape="height_map", height_map=str(tmp_path / "thin.npy"), map_pixel_size=1 / 32,
               spacing=1 / 32, f_th=0.0, max_indent=0.01, step=1e-3)


def test_cutoffs_with_no_wavevector_between_them_are_refused_early():
    """They passed validation and the run stopped with a traceback from the synthesis."""
    p = dict(shape="flat_punch", radius=0.5, f_th=0.0, spacing="1/32", extent=1.0, max_indent=0.01,
             step=1e-3, rms_height=0.01, short_cutoff=0.95, long_cutoff=1.0)
    with pytest.raises(ParameterError, match="short_cutoff / long_cutoff: no wavevector of the grid"):
        Params.from_dict({**p, "rolloff": 0.0})
    Params.from_dict({**p, "rolloff": 1.0})          # power below the long cutoff: a surface


def test_has_modes_is_the_synthesis_mask():
    """The validation's count of modes, without the n x n array, against the PSD's mask."""
    from tfm.surfaces import has_modes, self_affine_psd, wavevectors

    rng = np.random.default_rng(1)
    for _ in range(500):
        n = int(rng.integers(3, 40))
        sp = 1.0 / n
        short = float(rng.uniform(2 * sp, 1.2))
        long_ = float(rng.uniform(short, 1.3)) if rng.random() < 0.8 else None
        rolloff = 0.0 if rng.random() < 0.7 else 1.0
        mask = self_affine_psd(wavevectors(n, sp), 0.8, short, long_, rolloff) > 0
        assert mask.any() == has_modes(n, sp, short, long_, rolloff), (n, short, long_, rolloff)


def test_a_topography_s_own_pixel_size_given_again_is_the_same_run(tmp_path):
    """map_pixel_size equal to the file's own pixel size is the same physics as leaving it
    out, but it made a second run id (a campaign would compute the run twice)."""
    path = _topography(tmp_path, "own.nc", np.random.default_rng(3).normal(size=(20, 20)), (20.0, 20.0), "um")
    kw = dict(SI_MAP, height_map=path, spacing=1e-6, max_indent=1e-7, step=1e-8)
    bare = Params(**kw)
    again = Params(**kw, map_pixel_size=1e-6)
    assert again.map_pixel_size is None and again.run_id == bare.run_id


@pytest.mark.parametrize("layout", ["hexagonal", "jittered"])
def test_a_map_on_another_layout_gets_a_grid_it_covers(tmp_path, layout):
    """With the automatic extent, a height map on the hexagonal or jittered layout was
    always refused ("smaller than the grid"; a finer spacing did not help): the grid took
    the square grid's half-width, and those layouts reach further (a user's hunt). Now the
    grid is the largest of the layout that the map covers, and its springs read the map."""
    m = tmp_path / "m.npy"
    np.save(m, 1e-3 * np.random.default_rng(0).standard_normal((129, 129)))
    for spacing in ("1/32", "1/48"):
        p = Params.from_dict(dict(shape="height_map", height_map=str(m), map_pixel_size="1/64", spacing=spacing,
                                  f_th=0, max_indent=0.01, step=5e-4, layout=layout, operator="direct"))
        lay = make_layout(p)
        reach = 64 / 64                                    # 64 pixels each side of the centre
        assert max(np.abs(lay.x).max(), np.abs(lay.y).max()) <= reach * (1 + 1e-12)
        # and no smaller than one step of the layout short of it
        step = p.spacing * (np.sqrt(3) / 2 if layout == "hexagonal" else 1.0)
        assert max(np.abs(lay.x).max(), np.abs(lay.y).max()) > reach - step - p.jitter * p.spacing - 1e-12
        assert np.isfinite(heights(p, lay)).all()


def test_a_jittered_grid_too_large_for_its_map_names_the_jitters_reach(tmp_path):
    """--extent 1 on a map covering +-1 was refused with "grid (half-width 1.00781)", a
    number no one gave: the extent plus the jitter's reach (a user's hunt)."""
    m = tmp_path / "m.npy"
    np.save(m, np.zeros((65, 65)))
    with pytest.raises(ParameterError, match=r"covers \+-1, smaller than the grid \(half-width 1.00781: "
                                             r"extent 1 plus the jitter's reach, 0.25 spacings\)"):
        Params.from_dict(dict(shape="height_map", height_map=str(m), map_pixel_size="1/32", spacing="1/32",
                              f_th=0, max_indent=0.01, step=5e-4, layout="jittered", operator="direct",
                              extent=1))


# ---- messages that name the real cause (a user's hunt, 2026-11-25) --------------------
SMOOTH = dict(shape="paraboloid", k_th=0.04, spacing="1/32", extent=0.75, max_indent=0.1, step=1e-3)


@pytest.mark.parametrize("key, value", [("long_cutoff", 0.01), ("short_cutoff", 0.01), ("long_cutoff", 5.0)])
def test_a_roughness_cutoff_on_a_smooth_surface_is_refused_as_having_no_effect(key, value):
    """Its range was checked first: long_cutoff 0.01 was refused as "short_cutoff: must be <
    long_cutoff", a parameter never given; fixing the range then met "has no effect"."""
    with pytest.raises(ParameterError, match=rf"^{key}: {value!r} has no effect here; it applies only when the "
                                             "surface is rough"):
        Params.from_dict(dict(SMOOTH, **{key: value}))


def test_height_maps_too_small_say_so_and_not_to_change_the_spacing(tmp_path):
    from tfm.guards import check

    np.save(tmp_path / "two.npy", np.zeros((2, 2)))
    with pytest.raises(ParameterError, match=r"the map \(2 x 2 pixels\) has fewer than 3 pixels along x and y: "
                                             r".* needs at least 3 x 3 pixels \(use a larger map\)$"):
        Params.from_dict(dict(shape="height_map", height_map=str(tmp_path / "two.npy"), spacing="1/32", f_th=0,
                              max_indent=0.01, step=5e-4))
    np.save(tmp_path / "tiny.npy", np.zeros((3, 3)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # no map_pixel_size: warned, the point of this case
        tiny = Params.from_dict(dict(shape="height_map", height_map=str(tmp_path / "tiny.npy"), spacing="1/32",
                                     f_th=0, max_indent=0.01, step=5e-4, allow="coarse"))
    (note,) = [n for n in check(tiny, memory=False) if n.startswith("allowed past the 'coarse' guard")]
    assert "a finer spacing shrinks the map with it: use a larger map, or give map_pixel_size" in note
    assert "Refine the spacing or preload deeper" not in note


def test_a_square_map_on_a_jittered_layout_is_not_called_oblong(tmp_path):
    from tfm.surfaces import map_unused_note

    np.save(tmp_path / "map.npy", np.zeros((129, 129)))
    base = dict(shape="height_map", height_map=str(tmp_path / "map.npy"), map_pixel_size="1/64", spacing="1/32",
                f_th=0, max_indent=0.01, step=5e-4)
    note = map_unused_note(Params.from_dict(dict(base, layout="jittered", operator="direct")))
    assert note.startswith("height_map: the jittered layout's springs lie up to 0.9766 from the centre on a grid "
                           "of half-width 0.9688 (jitter 0.25 spacings beyond it)")
    assert "largest centred square" not in note
    np.save(tmp_path / "oblong.npy", np.zeros((129, 65)))
    oblong = map_unused_note(Params.from_dict(dict(base, height_map=str(tmp_path / "oblong.npy"), layout="jittered",
                                                   operator="direct")))
    assert "largest centred square" in oblong
