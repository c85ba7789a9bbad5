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
figures
    Residual maps and polar diagrams of a diagnosis.
command
    ``irreflect diagnose DATA [--model NAME] [--json] [--out DIR]``.
section
    The report section (:func:`reproduce_section`).
"""

from ..models.extensions import (
    CATALOGUE,
    EXTENSIONS,
    Extension,
    extend,
    extension_names,
    get_extension,
    register_extension,
)
from .command import register
from .workflow import (
    EFFECTS_FOUND,
    NO_MISSING_EFFECT,
    UNEXPLAINED,
    Diagnosis,
    diagnose,
    estimate_noise,
    structure_tests,
)


def reproduce_section(ctx):
    """The report section of the discrepancy workflow (see :mod:`.section`)."""
    from .section import reproduce_section as _section

    return _section(ctx)


__all__ = [
    "CATALOGUE", "EFFECTS_FOUND", "EXTENSIONS", "NO_MISSING_EFFECT", "UNEXPLAINED", "Diagnosis",
    "Extension", "diagnose", "estimate_noise", "extend", "extension_names", "get_extension",
    "register", "register_extension", "reproduce_section", "structure_tests",
]
