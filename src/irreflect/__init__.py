"""irreflect: reflection models for infrared and visible-light indoor multipath.

Fit the paper's two-component model (and others) to goniometer measurements, choose the
few measurement points that pin it down, design protocols, compare models and diagnose
what a model is missing. Angles in degrees at the edges, radians inside.
"""

from .data import Measurements, read_measurements, validate_table, write_measurements
from .errors import DataError, FitError, IrreflectError, UnknownNameError
from .fitting import FitResult, fit, fit_subsets
from .model import ReflectionModel, get_model, model_names

__all__ = [
    "DataError", "FitError", "FitResult", "IrreflectError", "Measurements", "ReflectionModel",
    "UnknownNameError", "fit", "fit_subsets", "get_model", "model_names", "read_measurements",
    "validate_table", "write_measurements",
]
__version__ = "0.1.0"
