"""The discrepancy workflow: find where a model and the measurements disagree, name the
missing effect (or say which effects the data cannot tell apart, and what to measure to
separate them), extend the model and show the gap shrink.

>>> from irreflect.diagnose import diagnose
>>> d = diagnose("table.csv")                      # doctest: +SKIP
>>> print(d.report()); d.to_dict()["verdict"]      # doctest: +SKIP

Modules
-------
extensions
    The catalogue of model extensions (``incidence_reflectance``, ``offspecular_peak``,
    ``retroreflection``, ``angle_offset``, ``background``, ``specular_halo``), their
    registry (:func:`register_extension`) and :func:`extend`; beside them the gain drift
    between angles of incidence of one table (:data:`GAIN_DRIFT`, a measurement
    artefact), which the diagnosis builds per table.
workflow
    Residual structure tests, the search over explanations, the verdict (:func:`diagnose`).
noise
    The noise estimate (additive and proportional to the signal) and the likelihood that
    compares explanations.
search
    The nesting order of extensions, warm starts and scans of the coordinates they add.
separate
    The measurements that would separate explanations the data cannot tell apart.
hidden
    Synthetic tables with a hidden effect (catalogue forms), to test the workflow blind.
blind
    A harder blind set: glossy, medium-gloss and matte bases with a saturating specular
    share, one or two effects in forms not the catalogue's, proportional noise, weak
    effects, varied grids.
The command ``irreflect diagnose``: :mod:`irreflect.cli.diagnose`; figures and ``--out``
files: :mod:`irreflect.plots.diagnose`; the report section: :mod:`irreflect.report.diagnose`.
"""

from ..models.extensions import (
    CATALOGUE,
    EXTENSIONS,
    GAIN_DRIFT,
    Extension,
    extension_names,
    get_extension,
    register_extension,
)
from ..models.registry import extend
from .workflow import (
    AMBIGUOUS,
    EFFECTS_FOUND,
    NO_MISSING_EFFECT,
    UNEXPLAINED,
    Diagnosis,
    diagnose,
    estimate_noise,
    structure_tests,
)

__all__ = [
    "AMBIGUOUS", "CATALOGUE", "EFFECTS_FOUND", "EXTENSIONS", "GAIN_DRIFT", "NO_MISSING_EFFECT",
    "UNEXPLAINED",
    "Diagnosis", "Extension", "diagnose", "estimate_noise", "extend", "extension_names",
    "get_extension", "register_extension", "structure_tests",
]
