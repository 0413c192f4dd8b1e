"""tfm: the threshold-force model of adhesion and mode I fracture (Hulikal, Bhattacharya &
Lapusta), as a Numba-parallel batch experiment engine."""
__version__ = "0.1.0"

from .params import ParameterError, Params  # noqa: E402
from .simulate import RunWarning, simulate  # noqa: E402

__all__ = ["Params", "ParameterError", "RunWarning", "simulate", "__version__"]
