"""tfm: the threshold-force model of adhesion and mode I fracture (Hulikal, Bhattacharya &
Lapusta), as a Numba-parallel batch experiment engine."""
import importlib
import importlib.util
import sys
import types

__version__ = "0.1.0"

from .params import ParameterError, ParameterWarning, Params  # noqa: E402

__all__ = ["Params", "ParameterError", "ParameterWarning", "GuardError", "RunWarning", "simulate",
           "__version__"]


def __getattr__(name):
    # the engine (NumPy, SciPy, Numba) loads on first use, so `tfm --help` stays fast
    if name in ("simulate", "RunWarning"):
        return getattr(importlib.import_module(".simulate", __name__), name)
    if name == "GuardError":
        return importlib.import_module(".guards", __name__).GuardError
    # submodules as attributes after a bare `import tfm` (tfm.results.read_metadata, ...)
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'tfm' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """``tfm.simulate`` is the function, as with an eager ``from .simulate import simulate``:
    importing the submodule tfm.simulate sets the package attribute to the module, and
    this keeps the function there instead."""

    def __setattr__(self, name, value):
        if name == "simulate" and isinstance(value, types.ModuleType):
            value = value.simulate
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
