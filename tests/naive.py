"""Slow, obvious reference implementations (the twins of the fast paths)."""
import numpy as np


def compliance_double_loop(x, y, diag, kind, cutoff):
    """The dense compliance matrix by a plain double loop (tiny N only)."""
    n = x.size
    C = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if i == j:
                C[i, j] = diag[i]
                continue
            r = np.hypot(x[i] - x[j], y[i] - y[j])
            if kind == "boussinesq" or (kind == "neighbors" and r <= cutoff * (1 + 1e-12)):
                C[i, j] = 1.0 / r
    return C


def algorithm1_dense(C, x0, f_th, d_values, max_rounds=1000):
    """The paper's Algorithm 1 with a dense matrix and np.linalg.solve: every spring in
    contact above F_th snaps and every penetrating spring enters, all at once."""
    n = x0.size
    contact = np.zeros(n, dtype=bool)
    F = np.zeros(n)
    rows = []
    for d in d_values:
        for _ in range(max_rounds):
            idx = np.flatnonzero(contact)
            F[:] = 0.0
            if idx.size:
                F[idx] = np.linalg.solve(C[np.ix_(idx, idx)], d - x0[idx])
            u = C @ F
            over = contact & (F > f_th + 1e-9 * np.abs(F).max(initial=0))
            into = ~contact & (x0 + u > d + 1e-9 * max(abs(d), np.abs(u).max()))
            if not over.any() and not into.any():
                break
            contact[over] = False
            contact[into] = True
        rows.append((d, -F.sum(), int(contact.sum())))
    return np.array(rows)
