"""``irreflect fit``, ``irreflect plot`` and ``irreflect models``."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import warnings

from .options import (
    POSITIVE,
    SEED,
    add_data_argument,
    add_ignore_sigma_argument,
    add_model_argument,
    add_resolution_argument,
    load_data,
    print_json,
)
from .options import single_fit_engine as _engine


def _check_model_and_resolution(model: str, resolution: float) -> None:
    """The model's name, and that a fit at one angle of incidence ('@G') is not asked to
    average over a receiver, checked before any work."""
    from ..models import parse_spec

    spec = parse_spec(model)
    spec.model()  # ('phong@10' included)
    if resolution and spec.at_gamma_deg is not None:
        from ..errors import IrreflectError

        raise IrreflectError(f"--resolution with model '{model}': a fit at one angle of "
                             "incidence ('@G') takes the readings as points; drop '@G' or "
                             "--resolution")


def _cmd_fit(args) -> int:
    from .._atomic import claim_output

    model = args.model
    _check_model_and_resolution(model, args.resolution)
    if args.save is None and (args.reflectance is not None or args.wavelength is not None
                              or args.notes is not None):
        from ..errors import IrreflectError

        raise IrreflectError("--reflectance, --wavelength and --notes go into the material "
                             "file: add --save MATERIAL.json")
    if args.save is not None and args.reflectance is not None:
        from ..room.materials import parse_reflectance

        parse_reflectance(args.reflectance, "--reflectance")  # before the fit, not after
    claim = (claim_output(args.save, "file", "--save", suffixes=(".json",))
             if args.save is not None else contextlib.nullcontext())
    with claim:  # the material file's path is checked and locked before any work
        meas = load_data(args)  # with --ignore-sigma, without its sigma column
        # resolution 0: the plain fit
        result, said = _fit_holding_warnings(meas, model, args)
        unweighted = math.nan
        if meas.sigma is not None:
            from ..fitting import weights_check

            text, unweighted = weights_check(meas, result, model, args.resolution,
                                             args.seed or 0)
            if text:  # said, and carried by the material file
                said, result, text = _one_chi2_warning(said, result, text)
                print(f"irreflect: warning: {meas.name}, {result.model}: {text}",
                      file=sys.stderr)
                result = dataclasses.replace(result, warnings=result.warnings + (text,))
        _pass_on(said)
        from ..data import saturation_note

        clipped = saturation_note(meas.gamma_deg, meas.power, meas.name)
        if clipped:  # noted when the table was read; the material file carries it too
            result = dataclasses.replace(result, warnings=result.warnings + (clipped,))
        if args.save is not None:
            from ..room.materials import save_material

            notes = args.notes
            if args.resolution:
                told = (f"fitted as the model averaged over the receiver's {args.resolution:g} "
                        "deg resolution (the coefficients are the material's)")
                notes = told if notes is None else f"{notes}; {told}"
            save_material(result, args.save, data_file=args.data, wavelength_nm=args.wavelength,
                          notes=notes, reflectance=args.reflectance)
    if args.resolution:
        from ..models.aperture import unresolved

        widths = {-abs(a.gamma_deg): a.lobe_half_width_deg for a in result.verdict().angles}
        text = unresolved(widths, args.resolution)
        if text:
            print(f"irreflect: warning: {meas.name}: {text}", file=sys.stderr)
    on_all = result.on_all_points  # 'MODEL@G': fitted on one incidence, scored on all
    if args.json:
        d = result.to_dict()
        print_json({k: d[k] for k in ("model", "params", "stderr", "r2", "rmse", "mse",
                                      "n_points", "fit_ms", "converged", "message",
                                      "at_bound", "ill_determined", "warnings", "verdict")}
                   | {"polar_error_pct": result.polar_errors()}
                   | ({"on_all_points": on_all} if on_all else {})
                   | ({"unweighted_r2": unweighted} if math.isfinite(unweighted) else {}))
    else:
        print(f"{meas.name}: {meas.n_points} points, angles of incidence "
              f"{', '.join(f'{g:g}' for g in meas.gammas)} deg")
        print(result.report(warnings=False))  # the warnings go to stderr
        if on_all:
            print(f"fitted on the {result.n_points} points of one angle of incidence; on all "
                  f"{on_all['n_points']} points: R^2 = {on_all['r2']:.6f}   RMSE = "
                  f"{on_all['rmse']:.6g}")
        if args.save is not None:
            print(f"wrote {args.save} (material file for 'irreflect room' scenes)")
    return 0


def _cmd_plot(args) -> int:
    from .._atomic import claim_output
    from ..plots import plot_polar, save_figure

    model = args.model or "two-lobe"
    _check_model_and_resolution(model, args.resolution)
    unused = [o for o, v in (("--model", args.model), ("--seed", args.seed),
                             ("--resolution", args.resolution or None),
                             ("--ignore-sigma", args.ignore_sigma or None)) if v is not None]
    if unused and not args.fit:
        print(f"irreflect: warning: {' and '.join(unused)} {'has' if len(unused) == 1 else 'have'}"
              " no effect without --fit (the figure then draws the readings only)",
              file=sys.stderr)
    with claim_output(args.out, "file", "--out", suffixes=(".png", ".svg", ".pdf")):
        meas = load_data(args)
        predict, title = None, meas.name
        if args.fit:
            # with a resolution, the curve drawn is what the receiver reads
            result, said = _fit_holding_warnings(meas, model, args)
            _pass_on(_warn_if_sigma_decides(meas, result, model, args, said))
            predict = result.predict
            title = f"{meas.name}: {result.model} fit, R^2 = {result.r2:.4f}"
            if args.resolution:
                title += f" (averaged over {args.resolution:g} deg)"
        ax = plot_polar(meas, predict, title=title, radius=args.radius)
        save_figure(ax.figure, args.out)
    print(f"wrote {args.out}")
    return 0


def _fit_holding_warnings(meas, model: str, args):
    """``fit`` and ``plot --fit``'s fit, and the warnings it issued, held back until the
    weights check has said whether one of them is folded into its own
    (:func:`_one_chi2_warning`); :func:`_pass_on` issues the rest."""
    from ..fitting import fit_averaged

    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = fit_averaged(meas, model, args.resolution, seed=args.seed or 0,
                              engine=_engine(meas.n_points))
    return result, said


def _pass_on(said) -> None:
    """The held-back warnings, on to the command's notes."""
    for w in said:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _one_chi2_warning(said, result, text: str):
    """``(said, result, text)`` with the fit's chi^2/dof warning (``sigma_note``) left out of
    the caught warnings and of ``result.warnings``, and what it adds folded into the weights
    warning ``text``: both spoke of the same chi^2 (an unseen table with a sigma column gave
    "misfits beyond the noise (reduced chi^2 59)" and "depart from the fit by chi^2/dof 59"
    on two lines)."""
    from ..fitting.results import SIGMA_NOTE_HEAD

    notes = [w for w in result.warnings if w.startswith(SIGMA_NOTE_HEAD)]
    if not notes:
        return said, result, text
    said = [w for w in said if SIGMA_NOTE_HEAD not in str(w.message)]
    result = dataclasses.replace(result, warnings=tuple(w for w in result.warnings
                                                        if w not in notes))
    scaled = notes[0].split(" (scaled by sqrt(chi^2/dof), ")
    more = f"; scaled by sqrt(chi^2/dof), {scaled[1][:-1]}" if len(scaled) > 1 else ""
    return said, result, (f"{text}. Its standard errors take sigma as given and understate "
                          f"the uncertainty{more}; irreflect diagnose names what the model "
                          "lacks")


def _warn_if_sigma_decides(meas, result, model: str, args, said):
    """The weighted fit drawn by ``plot --fit`` is warned of as ``fit`` warns of it (one
    warning of its chi^2: :func:`_one_chi2_warning`); returns the fit's other warnings."""
    if meas.sigma is None:
        return said
    from ..fitting import weights_check

    text, _ = weights_check(meas, result, model, args.resolution, args.seed or 0)
    if text:
        said, result, text = _one_chi2_warning(said, result, text)
        text = text.replace("irreflect fit --ignore-sigma", "irreflect plot --fit --ignore-sigma")
        print(f"irreflect: warning: {meas.name}, {result.model}: {text}", file=sys.stderr)
    return said


def _cmd_models(args) -> int:
    from ..models import get_model, model_names
    from ..models.extensions import EXTENSIONS

    for name in model_names():
        m = get_model(name)
        print(f"{name:<18} {m.n_params:>2} parameters  {m.formula}")
    print("extensions (append with '+', e.g. two-lobe+background): " + ", ".join(EXTENSIONS))
    return 0


def register(sub) -> None:
    p = sub.add_parser("fit", help="fit a reflection model to a measurement table",
                       description="Fit a reflection model and print coefficients with standard "
                                   "errors, R^2, RMSE, MSE and the per-gamma polar-area error.")
    add_data_argument(p)
    add_model_argument(p)
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the random extra starts (default 0)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    add_ignore_sigma_argument(p)
    add_resolution_argument(p, "the readings are fitted as the model averaged over it, so "
                               "the coefficients are the material's")
    p.add_argument("--save", metavar="MATERIAL.json",
                   help="also write the fit as a material file for room scenes (default: no)")
    p.add_argument("--reflectance", default=None, metavar="RHO|K",
                   help="with --save: total reflectance of the material (0..1), or K when the "
                        "power column is BRDF x cos(theta) in 1/sr (default: none, the scene "
                        "gives it)")
    p.add_argument("--wavelength", type=POSITIVE, default=None, metavar="NM",
                   help="with --save: wavelength of the measurement (nm; default: none)")
    p.add_argument("--notes", default=None,
                   help="with --save: free text kept in the file (default: none)")
    p.set_defaults(handler=_cmd_fit)

    p = sub.add_parser("plot", help="polar diagram per angle of incidence (Figs. 15-17)")
    add_data_argument(p)
    add_model_argument(p, what="reflection model, with --fit")
    p.set_defaults(model=None)  # two-lobe; None tells an unused --model from the default
    p.add_argument("--fit", action="store_true", help="draw the fitted model over the markers")
    add_ignore_sigma_argument(p)
    p.add_argument("--radius", choices=("auto", "linear", "log"), default="auto",
                   help="radius scale of the power (default auto: logarithmic when the "
                        "largest power is more than 100 times the 10th percentile, as on "
                        "glossy materials, else linear)")
    p.add_argument("--seed", type=SEED, default=None,
                   help="seed of the fit's random extra starts, with --fit (default 0)")
    add_resolution_argument(p, "with --fit, the model is fitted and drawn as its average "
                               "over it, as 'fit --resolution' fits")
    p.add_argument("--out", required=True, metavar="FILE.png",
                   help="figure file (.png, .svg or .pdf)")
    p.set_defaults(handler=_cmd_plot)

    p = sub.add_parser("models", help="list the reflection models and the extensions")
    p.set_defaults(handler=_cmd_models)
