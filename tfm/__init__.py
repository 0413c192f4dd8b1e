"""tfm: the threshold-force model of adhesion and mode I fracture (Hulikal, Bhattacharya &
Lapusta), as a Numba-parallel batch experiment engine."""
__version__ = "0.1.0"

from .params import ParameterError, Params  # noqa: E402

__all__ = ["Params", "ParameterError", "RunWarning", "simulate", "__version__"]


def __getattr__(name):
    # the engine (NumPy, SciPy, Numba) loads on first use, so `tfm --help` stays fast
    if name in ("simulate", "RunWarning"):
        from . import simulate as _module
        return getattr(_module, name)
    raise AttributeError(f"module 'tfm' has no attribute {name!r}")
