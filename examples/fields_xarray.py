"""Open a run's field snapshots with xarray and draw them.

    python examples/fields_xarray.py [OUTPUT_DIR]

Runs one adhesive paraboloid at spacing 1/32 with a snapshot every 10 steps (plus the
events: maximum load, pull-off, first snap, last step in contact), then reads the
NetCDF4 file with xarray and draws (a) the spring forces at pull-off, (b) the contact
radius from the fields against the one in the curve table. Writes OUTPUT_DIR/fields.png.
"""
import sys
import tempfile
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

import tfm
from tfm.plots import axis_label, draw_jump, fold_offsets, force_label, split_snap_off


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    res = tfm.simulate(spacing=1 / 32, alpha=0.75, k_th=0.02, shape="paraboloid", max_indent=0.05,
                       step=5e-4, snapshots=10)
    res.write_curve(out / "curve.parquet")          # the fields go beside it: curve.fields.nc

    ds = xr.open_dataset(out / "curve.fields.nc").sortby("step")      # the one line
    print(ds)
    k = ds.attrs["pull_off_step"]
    snap = ds.sel(step=k)
    in_contact = snap["state"] == 1
    print(f"pull-off at step {k}: sum F = {float(snap['F'].sum()):.6g} "
          f"(summary: {res.summary['pull_off_force']:.6g}), {int(in_contact.sum())} springs in contact")

    # contact radius sqrt(A / pi) from the fields, at every stored step
    area = (ds["area"] * (ds["state"] == 1)).sum(("x", "y"))
    radius = np.sqrt(area / np.pi)

    fig = Figure(figsize=(8.0, 3.2), layout="constrained")
    fig.get_layout_engine().set(wspace=0.1)          # room between (a)'s colour bar and (b)
    ax1, ax2 = fig.subplots(1, 2)
    snap["F"].where(in_contact).plot(ax=ax1, x="x", y="y", cmap="RdBu_r", center=0.0,
                                     cbar_kwargs={"label": axis_label("spring force $F$", "force", res.params, "tension > 0")})
    ax1.set_aspect("equal")
    ax1.set_title(f"(a) forces at pull-off, step {k}")
    ax2.plot(ds["force"], radius, "o", ms=3, label="from the fields")
    body, jump = split_snap_off(res.curve)          # the final snap-off is a jump, not a line
    line, = ax2.plot(body["force"], body["contact_radius"], "-", lw=0.8, label="curve table")
    if jump is not None:
        draw_jump(ax2, jump["force"], jump["contact_radius"], line.get_color())
    ax2.set_xlabel(force_label(res.params))                  # tfm's own labels, units included
    ax2.set_ylabel(axis_label("contact radius $a$", "length", res.params))
    ax2.set_title("(b) contact radius")
    # the corner the loop leaves free (by default the legend sat on the curve)
    ax2.legend(frameon=False, loc="lower right", fontsize="small")
    ax2.ticklabel_format(axis="x", style="sci", scilimits=(-2, 2), useMathText=True)   # x10^-3, as tfm's figures
    ax2.margins(y=0.08)                              # the plateau off the frame
    ax2.xaxis.set_major_locator(MaxNLocator(5))
    fold_offsets(fig)                                # the common factors into the axis labels
    fig.savefig(out / "fields.png", dpi=150)
    ds.close()
    print(f"wrote {out / 'fields.png'}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="tfm-example-")))
