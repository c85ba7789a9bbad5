"""Reflection models: the contract, the paper's and the literature's models, the catalogue
of extensions, and the one registry and grammar of model names.

=============================  =============================================================
``base``                       :class:`ReflectionModel` (the contract), :class:`Parameter`,
                               :class:`Geometry`, lobe building blocks
``guesses``                    data-driven starting values (per-angle lobe decomposition)
``paper``                      two-lobe (Eqs. 19-22), single-lobe (Eq. 6), N-lobe (Eq. 7),
                               Phong
``literature``                 Blinn-Phong, Lafortune, Ward, Torrance-Sparrow, Oren-Nayar
``extensions``                 the catalogue of effects a model may miss (diagnosis)
``registry``                   :data:`MODELS`, :func:`get_model`, the specification grammar
=============================  =============================================================

Adding a model: a module with a factory ``make_<name>() -> ReflectionModel`` and one line
in :data:`MODELS`; adding an extension: an :class:`Extension` and one line in
:data:`EXTENSIONS`. The contract tests cover both without edits.
"""

from .base import TWO_PI, Geometry, Parameter, ReflectionModel, generalized_lambertian
from .extensions import (
    CATALOGUE,
    EXTENSIONS,
    Extension,
    applied_extensions,
    base_of,
    extension_names,
    get_extension,
    register_extension,
)
from .guesses import (
    MAX_LOBE_INDEX,
    PROFILE_DIFFUSE_INDICES,
    PROFILE_SPECULAR_INDICES,
    LobeProfile,
    estimate_specular_index,
    lobe_profile,
    peak_directions,
)
from .paper import n_lobe_power, phong_power, single_lobe_power, two_lobe_power
from .registry import (
    MODELS,
    ModelSpec,
    extend,
    get_model,
    model_names,
    parse_spec,
    register_model,
)

__all__ = [
    "CATALOGUE", "EXTENSIONS", "Extension", "Geometry", "LobeProfile", "MAX_LOBE_INDEX",
    "MODELS", "ModelSpec", "PROFILE_DIFFUSE_INDICES", "PROFILE_SPECULAR_INDICES", "Parameter",
    "ReflectionModel", "TWO_PI", "applied_extensions", "base_of", "estimate_specular_index",
    "extend", "extension_names", "generalized_lambertian", "get_extension", "get_model",
    "lobe_profile", "model_names", "n_lobe_power", "parse_spec", "peak_directions",
    "phong_power", "register_extension", "register_model", "single_lobe_power", "two_lobe_power",
]
