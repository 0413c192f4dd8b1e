"""The tree's opening angle against the direct sum, on whole curves: how far theta moves
the pull-off (the README's "Tree operator" numbers and tfm.params.LOOSE_THETA's).

The standard curve (paraboloid R = 1, alpha 0.75, k_th 0.02, max_indent 0.05, step
2.5e-4) on a square grid at 1/48 and a jittered layout at 1/64 (jitter 0.2, seed 1):
per theta, the pull-off relative to the direct sum's, its indent against the direct
sum's, and whether every step had the same number of springs in contact.

    python -m bench.tree_pull_off          # a few minutes on 2 cores
"""
from __future__ import annotations

import warnings

import tfm

THETAS = (0.5, 0.7, 1.0)
CASES = (("square", 1 / 48, {}), ("jittered", 1 / 64, dict(jitter=0.2, seed=1)))
STANDARD = dict(alpha=0.75, k_th=0.02, shape="paraboloid", radius=1.0, max_indent=0.05, step=2.5e-4)


def main() -> None:
    warnings.simplefilter("ignore")         # theta 1 is flagged: that is what is measured
    print("| layout | spacing | theta | pull-off / direct - 1 | pull-off indent (direct) | same n_contact |")
    print("|---|---|---|---|---|---|")
    for layout, spacing, extra in CASES:
        base = dict(STANDARD, spacing=spacing, layout=layout, **extra)
        ref = tfm.simulate(operator="direct", **base)
        for theta in THETAS:
            run = tfm.simulate(operator="tree", theta=theta, **base)
            same = (len(run.curve) == len(ref.curve)
                    and bool((run.curve["n_contact"].to_numpy() == ref.curve["n_contact"].to_numpy()).all()))
            print(f"| {layout} | 1/{round(1 / spacing)} | {theta:g} | "
                  f"{run.summary['pull_off_force'] / ref.summary['pull_off_force'] - 1:+.2e} | "
                  f"{run.summary['pull_off_indent']:.5g} ({ref.summary['pull_off_indent']:.5g}) | {same} |",
                  flush=True)


if __name__ == "__main__":
    main()
