"""The compliance C applied to a force field: u_t = sum_s C_ts F_s.

C_ij = 1/r_ij off the diagonal (paper, Eq. 4, nondimensional), truncated at
``neighbor_rings * spacing`` for kernel="neighbors", absent for kernel="local"; the
diagonal is ``self_term / sqrt(A_i)`` (Love's regularization; the paper's 3.8/Delta on the
square grid) or ``c_w / A_i`` for the Winkler kernel.

Every operator has the same call: ``apply(src, f_src, tgt=None)`` with index arrays of
springs; ``tgt=None`` means every spring. The dense matrix is never formed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from .config import STENCIL_RADIUS, fft_workers
from .geometry import Layout
from .kernels.direct import BOUSSINESQ, LOCAL, NEIGHBORS, direct_sum
from .kernels.grid import gather_box, index_box, scatter_box, stencil_apply
from .params import ParameterError, Params


class IllPosedKernel(ParameterError):
    """The compliance matrix is not positive definite: the contact problem is ill-posed."""


@dataclass(frozen=True)
class KernelSpec:
    kind: int             # BOUSSINESQ, LOCAL or NEIGHBORS
    cutoff: float         # truncation radius for NEIGHBORS
    diag: np.ndarray      # C_ii per spring

    def offdiag(self, r: np.ndarray) -> np.ndarray:
        """C(r) for r > 0 (NumPy, used to build the FFT kernel and the slow references)."""
        with np.errstate(divide="ignore"):
            inv = np.where(r > 0, 1.0 / np.where(r > 0, r, 1.0), 0.0)
        if self.kind == LOCAL:
            return np.zeros_like(r)
        if self.kind == NEIGHBORS:
            return np.where(r <= self.cutoff * (1.0 + 1e-12), inv, 0.0)
        return inv


def kernel_spec(p: Params, layout: Layout) -> KernelSpec:
    if p.kernel == "local":
        return KernelSpec(LOCAL, 0.0, p.c_w / layout.area)
    diag = p.self_term / np.sqrt(layout.area)
    if p.kernel == "neighbors":
        return KernelSpec(NEIGHBORS, p.neighbor_rings * p.spacing, diag)
    return KernelSpec(BOUSSINESQ, math.inf, diag)


# --------------------------------------------------------------------------- FFT
def _grid_kernel(spec: KernelSpec, n: int, P: int, spacing: float, diag0: float) -> np.ndarray:
    """The kernel on a P x P periodic box, holding every offset |a|, |b| <= n - 1.

    With P >= 2n - 1 the circular convolution of a zero-padded n x n field equals the
    linear one: no periodic images."""
    a = np.arange(P)
    a = np.where(a < n, a, np.where(a > P - n, a - P, 0)).astype(float)
    keep = (np.arange(P) < n) | (np.arange(P) > P - n)
    r = np.hypot(a[:, None], a[None, :]) * spacing
    K = spec.offdiag(r) * (keep[:, None] & keep[None, :])
    K[0, 0] = diag0
    return K


def box_symbol(spec: KernelSpec, P: int, spacing: float) -> np.ndarray:
    """Real symbol of the kernel on a P x P periodic box: exact linear convolution for any
    sources and targets within a (P + 1) // 2 wide box."""
    K = _grid_kernel(spec, (P + 1) // 2, P, spacing, float(spec.diag[0]))
    # the kernel is real and even, so its transform is real up to round-off
    return sfft.rfft2(K).real.copy()


def grid_symbol(spec: KernelSpec, layout: Layout) -> tuple[np.ndarray, int]:
    """Symbol of the circulant embedding of C on the whole square grid, and its size P."""
    n = layout.shape[0]
    P = sfft.next_fast_len(2 * n - 1, real=True)
    return box_symbol(spec, P, layout.spacing), P


class FFTOperator:
    """Exact zero-padded convolution on the square grid (scipy.fft, fast sizes).

    The convolution runs on the bounding box (width w) of the sources and targets only,
    padded to a fast size P >= 2w - 1: inside the contact solve both are the contact set,
    far smaller than the grid. The transform is pruned: only the w non-zero rows are
    transformed along the rows, and only the w wanted rows are transformed back.
    Symbols are cached per P. Small transforms run on one thread (bench: thread start-up
    costs more than it saves below P ~ 512); pocketfft computes every 1-D transform the
    same way for any thread count, so results do not depend on it."""

    name = "fft"
    THREADED_SIZE = 512

    def __init__(self, spec: KernelSpec, layout: Layout, symbol=None):
        if layout.shape is None:
            raise ParameterError("operator: 'fft' needs a regular square grid")
        self.spec, self.spacing = spec, layout.spacing
        self.n = layout.shape[0]
        self.all = np.arange(layout.n)
        self.workers = fft_workers()
        self._symbols: dict[int, np.ndarray] = {}
        self._inverses: dict[int, np.ndarray] = {}
        if symbol is not None:
            self._symbols[symbol[1]] = symbol[0]

    def symbol(self, P: int) -> np.ndarray:
        if P not in self._symbols:
            self._symbols[P] = box_symbol(self.spec, P, self.spacing)
        return self._symbols[P]

    def inverse_symbol(self, P: int) -> np.ndarray:
        if P not in self._inverses:
            self._inverses[P] = 1.0 / self.symbol(P)
        return self._inverses[P]

    def apply_inverse(self, src, f_src, tgt=None):
        """C^-1 on the box of src and tgt (the FFT preconditioner): same transforms."""
        return self._convolve(src, f_src, tgt, self.inverse_symbol)

    def apply(self, src, f_src, tgt=None):
        return self._convolve(src, f_src, tgt, self.symbol)

    def _convolve(self, src, f_src, tgt, symbol_of):
        n = self.n
        if tgt is None:
            i0, j0, w, tgt = 0, 0, n, self.all
        elif tgt is src:
            i0, j0, w = index_box(n, src)
        else:
            i0, j0, w = index_box(n, np.concatenate((src, tgt)))
        w = max(w, 1)
        P = sfft.next_fast_len(2 * w - 1, real=True)
        workers = self.workers if P >= self.THREADED_SIZE else 1
        box = np.zeros((w, w))
        scatter_box(box, n, i0, j0, src, f_src)
        a = sfft.rfft(box, n=P, axis=1, workers=workers)
        a = sfft.fft(a, n=P, axis=0, workers=workers, overwrite_x=True)
        a *= symbol_of(P)
        a = sfft.ifft(a, axis=0, workers=workers, overwrite_x=True)[:w]
        u = sfft.irfft(a, n=P, axis=1, workers=workers)
        return gather_box(u, n, i0, j0, tgt)


class DirectOperator:
    """Numba parallel direct sum over the springs that carry force."""

    name = "direct"

    def __init__(self, spec: KernelSpec, layout: Layout):
        self.spec = spec
        self.x, self.y = layout.x, layout.y
        self.all = np.arange(layout.n)

    def apply(self, src, f_src, tgt=None):
        tgt = self.all if tgt is None else tgt
        return direct_sum(self.x, self.y, self.spec.diag, src, np.ascontiguousarray(f_src, dtype=float),
                          tgt, self.spec.kind, self.spec.cutoff)


def make_operator(p: Params, spec: KernelSpec, layout: Layout, symbol=None):
    if p.operator == "fft":
        return FFTOperator(spec, layout, symbol)
    if p.operator == "direct":
        return DirectOperator(spec, layout)
    from .tree_operator import TreeOperator
    return TreeOperator(spec, layout, theta=p.theta)


# ------------------------------------------------------------ positive definiteness
def check_positive_definite(p: Params, spec: KernelSpec, layout: Layout, symbol=None) -> float:
    """Refuse a compliance that is not positive definite; return the smallest symbol value.

    Square grid: the circulant embedding's symbol bounds the spectrum of the grid matrix
    (a principal submatrix), so min symbol > 0 proves positive definiteness; for a
    truncated kernel it samples the lattice symbol exactly, including the checkerboard.
    Other layouts: the smallest eigenvalue of the dense matrix of a central patch."""
    if spec.kind == LOCAL:
        return float(spec.diag.min())
    if layout.shape is not None:
        sym = symbol[0] if symbol is not None else grid_symbol(spec, layout)[0]
        smin = float(sym.min())
        scale = float(np.abs(sym).max())
    else:
        order = np.argsort(layout.x ** 2 + layout.y ** 2)[:1200]
        xs, ys = layout.x[order], layout.y[order]
        r = np.hypot(xs[:, None] - xs[None, :], ys[:, None] - ys[None, :])
        C = spec.offdiag(r)
        C[np.diag_indices_from(C)] = spec.diag[order]
        eig = np.linalg.eigvalsh(C)
        smin, scale = float(eig[0]), float(eig[-1])
    if smin <= 1e-12 * scale:
        what = f"kernel={p.kernel!r}"
        if p.kernel == "neighbors":
            what += f", neighbor_rings={p.neighbor_rings}"
        raise IllPosedKernel(
            f"kernel: the compliance with {what}, self_term={p.self_term:g} is not positive definite "
            f"(smallest symbol/eigenvalue {smin:.4g} against a largest of {scale:.4g}), so the contact "
            "problem is ill-posed. Raise self_term or change the kernel.")
    return smin


# ----------------------------------------------------------------- preconditioners
class StencilPreconditioner:
    """The inverse kernel, truncated to a (2m+1)^2 stencil, on the contact set.

    The inverse of the full-grid symbol is nearly local (it decays like r^-3 for the
    1/r kernel), so a small stencil of it keeps CG iterations almost independent of
    the grid size. Truncation can make the stencil slightly indefinite near k = 0; the
    centre is raised until its own symbol is positive, so PCG stays valid."""

    name = "stencil"

    def __init__(self, symbol, P, n, m=STENCIL_RADIUS):
        kinv = sfft.irfft2(1.0 / symbol, s=(P, P))
        idx = np.r_[np.arange(-m, 0) % P, np.arange(0, m + 1)]
        st = kinv[np.ix_(idx, idx)].copy()
        box = max(64, 4 * m + 4)
        pad = np.zeros((box, box))
        pad[: 2 * m + 1, : 2 * m + 1] = st
        smin = sfft.fft2(pad).real.min()
        if smin <= 0:
            st[m, m] += -smin + 1e-3 * abs(st[m, m])
        self.stencil = np.ascontiguousarray(st)
        self.n = n

    def __call__(self, idx, r):
        return stencil_apply(idx // self.n, idx % self.n, r, self.n, self.stencil)


class FFTPreconditioner:
    """R C^-1 R^T with the inverse symbol on the contact's box (two FFTs per application)."""

    name = "fft"

    def __init__(self, op: FFTOperator):
        self.op = op            # shares the operator's symbol cache

    def __call__(self, idx, r):
        return self.op.apply_inverse(idx, r, idx)


class DiagonalPreconditioner:
    name = "diagonal"

    def __init__(self, diag):
        self.inv = 1.0 / diag

    def __call__(self, idx, r):
        return self.inv[idx] * r


def make_preconditioner(p: Params, spec: KernelSpec, layout: Layout, symbol=None, operator=None):
    choice = p.preconditioner
    if choice == "auto":
        # On the grid the FFT inverse halves-to-thirds the CG iterations of the stencil at
        # twice the cost per iteration (bench: fewer FFTs per curve); the Winkler kernel is
        # diagonal, so its inverse diagonal is exact.
        if spec.kind == LOCAL:
            choice = "diagonal"
        else:
            choice = "fft" if layout.shape is not None else "diagonal"
    if choice == "none":
        return None
    if choice == "diagonal":
        return DiagonalPreconditioner(spec.diag)
    if choice == "stencil":
        sym, P = symbol if symbol is not None else grid_symbol(spec, layout)
        return StencilPreconditioner(sym, P, layout.shape[0])
    fft = operator if isinstance(operator, FFTOperator) else FFTOperator(spec, layout, symbol)
    return FFTPreconditioner(fft)
