"""irreflect: reflection models for infrared and visible-light indoor multipath.

Fit the paper's two-component model (and others) to goniometer measurements, choose the
few measurement points that pin it down, design protocols, compare models and diagnose
what a model is missing. Angles in degrees at the edges, radians inside.

The public names below are imported on first use (PEP 562), so that ``import irreflect``
and ``irreflect --version`` do not pay for pandas, scipy and the fitter.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: public name -> the module that defines it
_PUBLIC = {
    "Measurements": "data", "read_measurements": "data", "validate_table": "data",
    "write_measurements": "data",
    "DataError": "errors", "FitError": "errors", "FitWarning": "errors",
    "IrreflectError": "errors", "UnknownNameError": "errors", "SchemaError": "errors",
    "SceneError": "errors",
    "FitResult": "fitting", "fit": "fitting", "fit_subsets": "fitting",
    "ReflectionModel": "models", "get_model": "models", "model_names": "models",
    "parse_spec": "models", "register_model": "models",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'irreflect' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
