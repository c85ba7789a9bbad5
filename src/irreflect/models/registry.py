"""The one registry of model names, and the one grammar of model specifications.

A model specification is ``name[:N][+extension...][@G]``:

``name``
    a registered model (:data:`MODELS`: the paper's and the literature's);
``:N``
    its size where it has one (``n-lobe:4``, ``lafortune:3``);
``+extension``
    catalogue extensions applied in order, innermost first
    (``two-lobe+background+angle_offset``; :mod:`irreflect.models.extensions`);
``@G``
    fit the model to the points of one angle of incidence ``|gamma| = G`` degrees only
    and apply it to all (the paper's Phong at 10 deg: ``phong@10``). This is about the
    data a fit sees, not the model, so :func:`get_model` refuses it and the commands that
    fit (``fit``, ``compare``) read it (:func:`parse_spec`).

Adding a model is one module with a ``make_<name>()`` factory plus one line in
:data:`MODELS`; the contract tests (``tests/test_contracts_models.py``) then cover it.
Models pickle as their specification (:func:`_reduce_model`, registered with copyreg).
"""

from __future__ import annotations

import copyreg
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ..errors import IrreflectError, unknown_name
from . import literature, paper
from .base import ReflectionModel
from .extensions import GainDrift, gain_drift, get_extension

#: name -> factory; the factory takes the ``:N`` size when the model has one.
MODELS: dict[str, Callable[..., ReflectionModel]] = {
    "two-lobe": paper.make_two_lobe,
    "single-lobe": paper.make_single_lobe,
    "n-lobe": paper.make_n_lobe,
    "phong": paper.make_phong,
    "blinn-phong": literature.make_blinn_phong,
    "lafortune": literature.make_lafortune,
    "ward": literature.make_ward,
    "torrance-sparrow": literature.make_torrance_sparrow,
    "torrance-sparrow-gaussian": literature.make_torrance_sparrow_gaussian,
    "oren-nayar": literature.make_oren_nayar,
}

_SPEC = re.compile(r"^(?P<name>[A-Za-z][\w-]*)(?::(?P<count>[^+@]*))?"
                   r"(?P<ext>(?:\+[^+@]*)*)(?:@(?P<at>.*))?$")


@dataclass(frozen=True)
class ModelSpec:
    """A parsed model specification (see the module docstring)."""

    name: str
    count: int | None = None
    extensions: tuple[str, ...] = ()
    at_gamma_deg: float | None = None

    @property
    def model_text(self) -> str:
        """The specification without ``@G``: what :func:`get_model` builds."""
        text = self.name + (f":{self.count}" if self.count is not None else "")
        return text + "".join(f"+{e}" for e in self.extensions)

    def __str__(self) -> str:
        at = f"@{self.at_gamma_deg:g}" if self.at_gamma_deg is not None else ""
        return self.model_text + at

    def model(self) -> ReflectionModel:
        return get_model(self.model_text)


def parse_spec(spec) -> ModelSpec:
    """Parse ``name[:N][+extension...][@G]`` (one-line errors that say what was expected)."""
    if isinstance(spec, ModelSpec):
        return spec
    if isinstance(spec, ReflectionModel):
        return parse_spec(spec.name)
    if not isinstance(spec, str) or not spec.strip():
        raise IrreflectError(
            f"model must be a specification like 'two-lobe', 'n-lobe:4', "
            f"'two-lobe+background' or 'phong@10'; found {spec!r}"
        )
    text = spec.strip()
    m = _SPEC.match(text)
    if m is None:
        raise IrreflectError(
            f"model '{text}': expected name[:N][+extension...][@G], e.g. 'n-lobe:4', "
            "'two-lobe+background' or 'phong@10'"
        )
    name = m["name"]
    if name not in MODELS:
        raise unknown_name("model", name, MODELS)
    count = None
    if m["count"] is not None:
        try:
            count = int(m["count"])
        except ValueError:
            raise IrreflectError(
                f"model '{text}': expected '{name}:<integer>', found ':{m['count']}'"
            ) from None
    extensions = tuple(e for e in m["ext"].split("+") if e) if m["ext"] else ()
    if m["ext"] and any(not e for e in m["ext"].split("+")[1:]):
        raise IrreflectError(f"model '{text}': an empty extension name after '+'")
    if extensions:
        for e in extensions:
            get_extension(e)  # one-line error listing the valid names
    at = None
    if m["at"] is not None:
        try:
            at = abs(float(m["at"]))
        except ValueError:
            raise IrreflectError(
                f"model '{text}': expected MODEL@G with G an angle of incidence in degrees "
                f"(e.g. phong@10), found '@{m['at']}'"
            ) from None
        if not at < 90.0:
            raise IrreflectError(f"model '{text}': the angle of incidence after '@' must be "
                                 f"below 90 degrees; found {at:g}")
    return ModelSpec(name, count, extensions, at)


def register_model(name: str, factory: Callable[..., ReflectionModel]) -> None:
    """Add (or replace) a model factory; every command and the contract tests see it."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z][\w-]*", name):
        raise IrreflectError(f"model name must be letters, digits, '_' or '-'; found {name!r}")
    if not callable(factory):
        raise IrreflectError(f"model '{name}': the factory must be callable, found "
                             f"{type(factory).__name__}")
    MODELS[name] = factory
    _MODEL_CACHE.clear()


_MODEL_CACHE: dict[str, ReflectionModel] = {}


def get_model(model) -> ReflectionModel:
    """The model of a specification ``name[:N][+extension...]`` (or a model, as given)."""
    if isinstance(model, ReflectionModel):
        return model
    if isinstance(model, str) and model in _MODEL_CACHE:
        return _MODEL_CACHE[model]
    spec = parse_spec(model)
    if spec.at_gamma_deg is not None:
        raise IrreflectError(
            f"model '{spec}': '@{spec.at_gamma_deg:g}' chooses the points a model is fitted "
            "to (one angle of incidence); give it where a fit is made (irreflect fit, "
            f"compare; in Python fit(data, '{spec}')), or the model alone "
            f"('{spec.model_text}')"
        )
    key = spec.model_text
    if key not in _MODEL_CACHE:
        factory = MODELS[spec.name]
        if spec.count is None:
            built = factory()
        else:
            try:
                built = factory(spec.count)
            except TypeError:
                raise IrreflectError(
                    f"model '{spec.name}' takes no ':{spec.count}' size") from None
        if not isinstance(built, ReflectionModel):
            raise IrreflectError(
                f"model '{spec.name}': its factory (register_model) must return a "
                f"ReflectionModel, found {type(built).__name__}: return an instance of a "
                "ReflectionModel subclass (docs/api.md, Models)")
        if spec.extensions:
            built = extend(built, spec.extensions)
        _MODEL_CACHE[key] = built
    if isinstance(model, str):
        _MODEL_CACHE[model] = _MODEL_CACHE[key]
    return _MODEL_CACHE[key]


def extend(base, names: str | Sequence[str]) -> ReflectionModel:
    """Apply extensions in order: ``extend("two-lobe", ["background", "angle_offset"])``.

    ``base`` a model or a model specification (:func:`get_model`); ``names`` may also be
    one string joined with ``+`` (``"background+angle_offset"``).
    """
    model = get_model(base)
    if isinstance(names, str):
        names = [n for n in names.split("+") if n]
    for name in names:
        model = get_extension(name)(model)
        if not isinstance(model, ReflectionModel):
            raise IrreflectError(
                f"extension '{name}' returned {type(model).__name__}, expected a ReflectionModel"
            )
    return model


def model_names() -> list[str]:
    """Every registered model name."""
    return sorted(MODELS)


def _reduce_model(model: ReflectionModel):
    """A model pickles as its registry specification (closures and bound data do not):
    loading it rebuilds the same model from the registry (:func:`get_model`). A gain
    drift (:func:`~irreflect.models.extensions.gain_drift`, built per table, outermost)
    is not in the registry: it pickles as the model it wraps and its angles of
    incidence."""
    if isinstance(model.extension, GainDrift) and model.wrapped is not None:
        return (_with_gain_drift, (model.wrapped, model.extension.levels_deg))
    return (get_model, (model.name,))


def _with_gain_drift(wrapped: ReflectionModel, levels_deg) -> ReflectionModel:
    return gain_drift(levels_deg)(wrapped)


copyreg.pickle(ReflectionModel, _reduce_model)
