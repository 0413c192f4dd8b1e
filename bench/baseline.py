"""The obvious plain SciPy engine, the yardstick of `make bench` (not used by tfm).

Standard curve: paraboloid R = 1, K_th = 0.02, alpha = 0.75, preload 0.05 in steps of
2.5e-4, then unload until no spring is in contact. Zero-padded rfft2 convolution of the
whole grid, unpreconditioned warm-started CG at tol 1e-10, the paper's batch rounds.
Usage: python bench/baseline.py [spacing, default 1/128]
"""
import sys
import time

import numpy as np
from scipy.fft import irfft2, next_fast_len, rfft2

h = 1.0 / float(sys.argv[1].split("/")[1]) if len(sys.argv) > 1 else 1.0 / 128
R, K_TH, ALPHA, DMAX, STEP, TOL = 1.0, 0.02, 0.75, 0.05, 2.5e-4, 1e-10
m = int(np.ceil((1.3 * np.sqrt(R * DMAX) + 4 * h) / h - 1e-9))     # tfm's auto extent
n = 2 * m + 1
c = np.arange(-m, m + 1) * h
X, Y = np.meshgrid(c, c, indexing="ij")
x0 = -(X ** 2 + Y ** 2) / (2 * R)
f_th = K_TH * (h * h) ** ALPHA
P = next_fast_len(2 * n - 1, real=True)                             # no periodic images
a = np.minimum(np.arange(P), P - np.arange(P)) * h
r = np.hypot(a[:, None], a[None, :])
K = np.where(r > 0, 1.0 / np.where(r > 0, r, 1.0), 3.8 / h)
Khat = rfft2(K)


def conv(F):                                   # u = C F on the whole grid
    return irfft2(rfft2(F, s=(P, P)) * Khat, s=(P, P))[:n, :n]


def cg(S, b, x):                               # C_SS x = b, warm start x
    def A(v):
        F = np.zeros((n, n))
        F[S] = v
        return conv(F)[S]
    rr = b - A(x)
    p, rs, bn = rr.copy(), rr @ rr, np.linalg.norm(b)
    while np.sqrt(rs) > TOL * bn:
        Ap = A(p)
        al = rs / (p @ Ap)
        x, rr = x + al * p, rr - al * Ap
        rs, rs_old = rr @ rr, rs
        p = rr + rs / rs_old * p
    return x


t0 = time.perf_counter()
S, F, fmax = np.zeros((n, n), bool), np.zeros((n, n)), 0.0
ds = [-STEP * k for k in range(1, int(round(DMAX / STEP)) + 1)]
d, k = ds[-1], 0
while k < len(ds) or S.any():
    d = ds[k] if k < len(ds) else d + STEP
    k += 1
    while True:                                # batch rounds: all violators at once
        F[~S] = 0.0
        if S.any():
            F[S] = cg(S, d - x0[S], F[S])
        u = conv(F)
        over, into = S & (F > f_th), ~S & (x0 + u > d)
        if not over.any() and not into.any():
            break
        S = (S & ~over) | into
        F[over] = 0.0
    fmax = max(fmax, F.sum())
print(f"baseline spacing 1/{round(1 / h)}: pull-off {fmax:.7g}, wall {time.perf_counter() - t0:.2f} s")
