"""The measurements behind tfm.guards' thresholds and memory estimate (docs/physics.md, 8).

    python -m bench.guards coarse|step|tol      # pull-off against the guarded quantity
    python -m bench.guards memory EXTENT [OPERATOR [LAYOUT]]   # peak RSS against the estimate

Paraboloid, R = 1, K_th = 0.02, alpha = 0.75, max_indent = 0.05 unless stated; not in CI.
"""
from __future__ import annotations

import math
import resource
import sys
import warnings

from tfm import Params, simulate
from tfm.guards import estimate_memory

BASE = dict(shape="paraboloid", k_th=0.02, alpha=0.75, radius=1.0, max_indent=0.05, step=2.5e-4,
            allow="coarse,step,tol,memory")


def pull_off(**kw) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(Params.from_dict({**BASE, **kw})).summary


def main(argv: list[str]) -> None:
    what = argv[0]
    if what == "coarse":
        for sp in ["1/4", "1/6", "1/8", "1/12", "1/16", "1/24", "1/32", "1/64", "1/128"]:
            for R, dm in [(1.0, 0.05), (0.5, 0.025)]:
                s = pull_off(spacing=sp, radius=R, max_indent=dm, step=dm / 200)
                h = eval(sp)  # noqa: S307 - a literal fraction from the list above
                print(f"spacing {sp} R {R} springs across a_Hertz {math.sqrt(R * dm) / h:.2f} "
                      f"pull_off {s['pull_off_force']:.5g}", flush=True)
    elif what == "step":
        for n in [2, 3, 5, 10, 20, 50, 100, 200, 400]:
            s = pull_off(spacing="1/32", step=0.05 / n)
            print(f"loading steps {n} pull_off {s['pull_off_force']:.6g}", flush=True)
    elif what == "tol":
        # a flipped snap decision shifts the pull-off by a step, at some spacings and steps
        # only: sweep both, against tol 1e-10
        for sp in ["1/32", "1/64", "1/128", "1/256"]:
            for step in [2.5e-4, 1e-3]:
                ref = pull_off(spacing=sp, step=step)["pull_off_force"]
                for tol in [1e-2, 1e-3, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6]:
                    f = pull_off(spacing=sp, tol=tol, step=step)["pull_off_force"]
                    print(f"spacing {sp} step {step:g} tol {tol:g} pull_off {f:.8g} "
                          f"relative to tol 1e-10 {(f - ref) / ref:+.2e}", flush=True)
    elif what == "memory":
        extent = float(argv[1])
        operator = argv[2] if len(argv) > 2 else "fft"
        layout = argv[3] if len(argv) > 3 else "square"
        kw = dict(shape="paraboloid", f_th=2e-5, alpha=0.0, max_indent=0.01, step=1e-3,
                  operator=operator, layout=layout, allow="memory")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            simulate(Params.from_dict({**kw, "spacing": "1/32", "extent": 0.3}))   # compile first
            before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            p = Params.from_dict({**kw, "spacing": "1/128", "extent": extent})
            res = simulate(p)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{operator} {layout} springs {res.summary['n_springs']} runtime {before:.0f} MiB "
              f"peak {peak:.0f} MiB estimate {estimate_memory(p) / 2**20:.0f} MiB")
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:] or ["help"])
