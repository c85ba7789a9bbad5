"""The discrepancy workflow: find where a model and the measurements disagree, name the
missing effect, extend the model and show the gap shrink.

>>> from irreflect.diagnose import diagnose
>>> d = diagnose("table.csv")                      # doctest: +SKIP
>>> print(d.report()); d.to_dict()["verdict"]      # doctest: +SKIP

Modules
-------
extensions
    The catalogue of model extensions (``incidence_reflectance``, ``offspecular_peak``,
    ``retroreflection``, ``angle_offset``, ``background``, ``specular_halo``), their
    registry (:func:`register_extension`) and :func:`extend`.
workflow
    Noise estimate, residual structure tests, candidate ranking, the loop and the verdict
    (:func:`diagnose`).
hidden
    Synthetic tables with a hidden effect, to test the workflow blind.
The command ``irreflect diagnose``: :mod:`irreflect.cli.diagnose`; figures and ``--out``
files: :mod:`irreflect.plots.diagnose`; the report section: :mod:`irreflect.report.diagnose`.
"""

from ..models.extensions import (
    CATALOGUE,
    EXTENSIONS,
    Extension,
    extension_names,
    get_extension,
    register_extension,
)
from ..models.registry import extend
from .workflow import (
    EFFECTS_FOUND,
    NO_MISSING_EFFECT,
    UNEXPLAINED,
    Diagnosis,
    diagnose,
    estimate_noise,
    structure_tests,
)

__all__ = [
    "CATALOGUE", "EFFECTS_FOUND", "EXTENSIONS", "NO_MISSING_EFFECT", "UNEXPLAINED", "Diagnosis",
    "Extension", "diagnose", "estimate_noise", "extend", "extension_names", "get_extension",
    "register_extension", "structure_tests",
]
