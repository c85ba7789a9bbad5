"""``irreflect next`` and ``irreflect campaign``: the adaptive measurement campaign.

``next MEASURED.csv`` proposes the next readings on a new material (an opening design when
MEASURED.csv holds only its header) and says whether to stop; ``campaign DENSE.csv``
replays campaigns (adaptive, the paper's protocol, the glossy-aware one, random readings,
``select``'s hindsight subsets) against a dense table used as the instrument.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

from .._text import count
from ..errors import IrreflectError
from .options import (
    ANGLE,
    ANGLES,
    NON_NEGATIVE,
    POSITIVE,
    POSITIVE_INT,
    SEED,
    Flatten,
    add_model_argument,
    add_resolution_argument,
    int_at_least,
    print_json,
)

#: Default angles of incidence of ``next`` (a goniometer set every 10 deg).
DEFAULT_GAMMAS = (-10.0, -20.0, -30.0, -40.0, -50.0, -60.0, -70.0)
#: The most readings ``next`` reads, and the largest dense table ``campaign`` replays on.
NEXT_MAX_READINGS = 2000
CAMPAIGN_MAX_POINTS = 20000


def _same_file(a, b) -> bool:
    try:
        return Path(a).exists() and Path(b).exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _instrument(args):
    from ..campaign import Instrument

    gammas = tuple(args.gammas) if args.gammas else DEFAULT_GAMMAS
    return Instrument(gammas_deg=gammas, theta_min=args.theta_min, theta_max=args.theta_max,
                      theta_step=args.theta_step, min_separation=args.min_separation,
                      source_clearance=args.source_clearance,
                      gamma_change_cost=args.gamma_cost,
                      max_gamma_settings=args.gamma_settings, resolution=args.resolution)


def _cmd_next(args) -> int:
    from .._atomic import claim_outputs

    if args.out is not None:
        from ..validation import check_output_path

        check_output_path(args.out, "file", "--out", (".csv",))
        if _same_file(args.out, args.measured) or (
                Path(args.out).absolute() == Path(args.measured).absolute()):
            raise IrreflectError(f"--out {args.out} is the input table: write the proposals "
                                 "to another file (irreflect never replaces an input)")
    if args.save is not None and (_same_file(args.save, args.measured) or (
            Path(args.save).absolute() == Path(args.measured).absolute())):
        raise IrreflectError(f"--save {args.save} is the input table: write the material to "
                             "another file (irreflect never replaces an input)")
    if args.save is not None and args.out is not None and (
            Path(args.save).absolute() == Path(args.out).absolute()):
        raise IrreflectError(f"--save and --out are both {args.out}: give two files")
    with claim_outputs((args.out, "file", "--out"),
                       (args.save, "file", "--save", (".json",))):
        return _next(args)


def _no_proposals():
    """The empty proposals table (every setting is measured: ``propose`` refuses)."""
    import pandas as pd

    return pd.DataFrame(columns=["gamma_deg", "theta_deg", "why", "new_gamma", "gain"])


def _next(args) -> int:
    from .._atomic import atomic_path
    from ..campaign import Campaign
    from ..campaign.io import read_readings
    from ..models import get_model

    model = get_model(args.model)
    tool = _instrument(args)
    readings = read_readings(args.measured, average_duplicates=args.average_duplicates,
                             max_rows=NEXT_MAX_READINGS)
    name = Path(args.measured).stem
    campaign = Campaign(tool, readings, model=model.name, seed=args.seed, name=name)
    # none left: printed as "no setting left to propose", with the verdict
    proposals = campaign.propose(args.n) if campaign.n_free else _no_proposals()
    verdict = campaign.verdict()
    if args.save is not None:
        if campaign.fit is None:
            need = model.n_params + 1
            if campaign.n_measured < need:
                raise IrreflectError(
                    f"--save: no fit of the readings to save yet "
                    f"({count(campaign.n_measured, 'reading')}; the first fit needs {need}): measure the proposed settings "
                    "first")
            raise IrreflectError(
                f"--save: no fit of the {count(campaign.n_measured, 'reading')} to save: "
                f"{verdict.reasons[0] if verdict.reasons else 'no usable fit'}")
        from ..room.materials import save_material

        save_material(campaign.fit, args.save, data_file=args.measured,
                      notes=_save_notes(campaign, verdict, tool))
    if args.out is not None:
        table = proposals[["gamma_deg", "theta_deg", "why"]].copy()
        table["new_gamma"] = proposals["new_gamma"].map({True: "yes", False: "no"})
        table["power"] = ""
        with atomic_path(args.out, "--out") as tmp:
            table.to_csv(tmp, index=False, float_format="%.6g")
    warned = _mirror_warnings(tool) + [w for w in (campaign.unresolved_lobe(),) if w]
    for text in warned:
        print(f"irreflect: warning: {text}", file=sys.stderr)
    readings = campaign.measurements  # Campaign.add warns of these notes (DataNotice)
    noted = [] if readings is None else tool.reading_notes(readings.gamma_deg,
                                                           readings.theta_deg)
    short = _fewer_than_asked(args.n, len(proposals), tool)
    if short:
        noted.append(short)
    if args.json:
        doc = {"dataset": name, "n_measured": campaign.n_measured,
               "instrument": tool.describe(), "model": model.name, "seed": args.seed,
               "proposals": [{"gamma_deg": float(r.gamma_deg), "theta_deg": float(r.theta_deg),
                              "why": r.why, "new_gamma": bool(r.new_gamma),
                              "gain": float(r.gain)} for r in proposals.itertuples()],
               "verdict": verdict.to_dict(), "warnings": warned, "notes": noted,
               "out": args.out, "save": args.save}
        print_json(doc)
        return 0
    if not args.gammas:
        print(f"irreflect: note: instrument angles of incidence "
              f"{', '.join(f'{g:g}' for g in DEFAULT_GAMMAS)} deg (the default; give "
              "--gammas to change)", file=sys.stderr)
    if short:
        print(f"irreflect: note: {short}", file=sys.stderr)
    print(f"{name}: {count(campaign.n_measured, 'reading')} so far; instrument: {tool.describe()}")
    if len(proposals):
        print(f"next {len(proposals)} setting(s), in measurement order:")
        for r in proposals.itertuples():
            print(f"  gamma {r.gamma_deg:7.4g}  theta {r.theta_deg:8.4g}   {r.why}")
    else:
        print("no setting left to propose: every setting of the instrument is measured or "
              f"within the minimum separation ({tool.min_separation:g} deg) of a reading at "
              "its angle of incidence")
    print(f"verdict: {verdict.text}")
    if args.out is not None:
        what = "setting" if len(proposals) == 1 else "settings"
        print(f"wrote {args.out} ({len(proposals)} {what}: fill in power and add the rows "
              f"to {Path(args.measured).name})")
    if args.save is not None:
        print(f"wrote {args.save} (the campaign's fit of {count(campaign.n_measured, 'reading')}: a "
              "material file for 'irreflect room' scenes)")
    return 0


def _fewer_than_asked(asked: int, proposed: int, tool) -> str:
    """A note when ``next`` proposes fewer settings than ``--n`` asked for (``--n 100000``
    printed "next 900 setting(s)" without a word on the rest), with the reason: every
    free setting is proposed, and the campaign scores at most
    :data:`~irreflect.campaign.instrument.MAX_SETTINGS` of the instrument's settings at
    once. No proposal at all has its own line ("no setting left to propose")."""
    from ..campaign.instrument import MAX_SETTINGS

    if not 0 < proposed < asked:
        return ""
    total = len(tool.settings())
    if total > MAX_SETTINGS:
        return (f"--n {asked:,} asked for more settings than the campaign scores: proposing "
                f"{proposed:,}, every free one of the {MAX_SETTINGS:,} (of the instrument's "
                f"{total:,}) it scores at once")
    return (f"--n {asked:,} asked for more settings than are free: proposing {proposed:,}, "
            "every setting not yet measured")


def _mirror_warnings(tool) -> list[str]:
    """A warning when the instrument cannot measure the specular peak (theta = -gamma) at
    some of its angles of incidence, with the reason for each: beyond the receiver's range
    (widen it) or within the source clearance (at normal incidence the mirror is the
    source direction); and when its nearest setting stands more than
    :data:`~irreflect.campaign.instrument.MIRROR_NEAR_DEG` from it (a coarse receiver step)."""
    from ..campaign.instrument import MIRROR_NEAR_DEG

    off = {g: d for g, d in tool.mirror_offsets().items() if d > MIRROR_NEAR_DEG + 1e-9}
    # a mirror direction beyond the range or within the source clearance: no step reaches
    # it, however near its nearest setting (gamma 0 at a step of 2.5 deg blamed the step)
    blocked_anyway = {g for g in off if tool.mirror_blocked(g)}
    off = {g: d for g, d in off.items() if g not in blocked_anyway}
    by_offset: dict[str, list[str]] = {}
    for g, d in off.items():
        by_offset.setdefault(f"{d:.3g}", []).append(f"{g:g}")
    coarse = (["the receiver's nearest setting to the specular peak (theta = -gamma) is "
               + "; ".join(f"{d} deg from it at gamma {', '.join(gs)}"
                           for d, gs in by_offset.items())
               + f": a glossy lobe narrower than that goes unmeasured there (a "
               f"--theta-step of {MIRROR_NEAR_DEG:g} deg or less near the mirror reaches it)"]
              if off else [])
    misses = set(tool.mirror_misses()) | blocked_anyway
    missed = [g for g in map(float, tool.gammas) if g in misses]
    if not missed:
        return coarse
    out_of_range = [g for g in missed if not tool.theta_min <= -g <= tool.theta_max]
    blocked = [g for g in missed if g not in out_of_range]
    parts = []
    if out_of_range:
        parts.append(f"{', '.join(f'{g:g}' for g in out_of_range)} deg (beyond the receiver "
                     f"range {tool.theta_min:g}..{tool.theta_max:g} deg: widen --theta-min/"
                     "--theta-max to measure it)")
    if blocked:
        parts.append(f"{', '.join(f'{g:g}' for g in blocked)} deg (within "
                     f"{tool.source_clearance:g} deg of the source direction, "
                     "--source-clearance)")
    return ["the specular peak (theta = -gamma) cannot be measured at gamma "
            + " and ".join(parts) + ": the fit extrapolates it there"] + coarse


def _cmd_campaign(args) -> int:
    from .._atomic import claim_output

    claim = (claim_output(args.out, "dir", "--out") if args.out is not None
             else contextlib.nullcontext())
    with claim:
        return _campaign(args)


def _campaign(args) -> int:
    from .._progress import progress
    from ..campaign import STRATEGIES, replay
    from ..data import read_measurements
    from ..errors import unknown_name
    from ..models import get_model
    from ..validation import check_points_budget, split_names

    model = get_model(args.model)
    strategies = split_names(args.strategies, "--strategies", "adaptive,paper")
    if not strategies:
        raise IrreflectError("--strategies: expected a comma-separated list of "
                             f"{', '.join(STRATEGIES)}; found none")
    for s in strategies:
        if s not in STRATEGIES:
            raise unknown_name("campaign strategy", s, STRATEGIES)
    if args.generations is not None and "hindsight" not in strategies:
        print("irreflect: warning: --generations has no effect: no strategy of --strategies "
              "is 'hindsight' (it sets the NSGA-II generations of its subsets)", file=sys.stderr)
    args.generations = 100 if args.generations is None else args.generations
    dense = read_measurements(args.data, average_duplicates=args.average_duplicates)
    check_points_budget(dense.n_points, "campaign", str(args.data))
    if dense.n_points > CAMPAIGN_MAX_POINTS:
        raise IrreflectError(
            f"{args.data}: {dense.n_points} measured points is more than 'campaign' replays "
            f"on ({CAMPAIGN_MAX_POINTS}): subsample the table")
    if args.method == "interpolate" and args.theta_step is None:
        args.theta_step = 1.0
    if args.method == "nearest" and args.theta_step is not None:
        # an option that does nothing is warned of (docs/bad-input.md), as --generations is
        print(f"irreflect: warning: --theta-step {args.theta_step:g} has no effect with "
              "--method nearest (the default: readings at the table's own angles); add "
              "--method interpolate to read every --theta-step deg", file=sys.stderr)
        args.theta_step = None
    bar = progress(len(strategies), desc=f"campaign {dense.name}", unit="strategies",
                   enabled=not args.json)
    try:
        def told(text):
            bar.set_postfix_str(text.split(": ", 1)[-1])
            bar.update(1)

        result = replay(dense, strategies, n_max=args.n_max, model=model.name, seed=args.seed,
                        method=args.method, tolerance_deg=args.tolerance,
                        theta_step=args.theta_step, noise=args.noise,
                        angle_error_deg=args.angle_error, generations=args.generations,
                        progress=told, resolution=args.resolution)
    finally:
        bar.close()
    for text in result.warnings:
        print(f"irreflect: warning: {text}", file=sys.stderr)
    if args.out is not None:
        _write_campaign(result, args.out)
    if args.json:
        print_json(result.to_dict())
        return 0
    print(format_replay(result))
    if args.out is not None:
        print(f"wrote {args.out}: r2_by_n.csv, summary.csv, replay.json, campaign.png")
    return 0


def _r2(v: float) -> str:
    """R^2 to four decimals, or in exponent form once a replayed fit's is far below zero
    (a random campaign's fit extrapolating: -1.35e+18, not -1349228816089424128.0000)."""
    return f"{v:.4f}" if v > -1e4 else f"{v:.3g}"


def format_replay(result) -> str:
    """The printed replay: the strategies' N to reach the target, then R^2 per N."""
    lines = [f"{result.dataset}: {result.n_points} points; all-points fit R^2 "
             f"{result.reference_r2:.4f}, target R^2 >= {result.target:.4f} (within 0.01)"]
    width = max(len(k) for k in result.curves) if result.curves else 8
    for name, c in result.curves.items():
        reached = c.reached(result.target)
        at12 = c.r2.get(12)
        text = (f"reaches the target at N = {reached} and keeps it" if reached is not None
                else "never keeps the target" if c.r2 else "not available")
        extra = "" if at12 is None else f"; R^2 {_r2(at12)} at N = 12"
        note = f"  ({c.note})" if c.note else ""
        lines.append(f"  {name:<{width}}  {text}{extra}{note}")
    if result.verdicts:
        stop = result.stop_n
        lines.append("  adaptive verdict: " + (f"stop at N = {stop}" if stop else
                                                 "never said stop")
                     + (f", R^2 {_r2(result.curves['adaptive'].r2.get(stop, float('nan')))} "
                        "there" if stop else ""))
    if result.proposal_seconds:
        t = sorted(result.proposal_seconds)
        lines.append(f"  adaptive: {len(t)} proposals, median {t[len(t) // 2]:.2f} s, "
                     f"slowest {t[-1]:.2f} s; whole campaign "
                     f"{result.curves['adaptive'].seconds:.1f} s")
    table = result.table()
    cols = [c for c in table.columns if c != "N"]
    lines.append("R^2 against all points by number of readings N:")
    lines.append("  " + f"{'N':>3}  " + "  ".join(f"{c:>10}" for c in cols))
    for row in table.itertuples(index=False):
        cells = []
        for v in row[1:]:
            if isinstance(v, str):
                cells.append(f"{v:>10}")
            elif v != v:
                cells.append(f"{'':>10}")
            else:
                cells.append(f"{_r2(v):>10}")
        lines.append("  " + f"{int(row[0]):>3}  " + "  ".join(cells))
    return "\n".join(lines)


def _write_campaign(result, out) -> None:
    from .._atomic import atomic_directory
    from .._jsonio import dumps
    from ..plots.campaign import plot_campaign
    from ..plots.common import save_figure

    with atomic_directory(out, "--out", "campaign") as tmp:
        tmp = Path(tmp)
        result.table().to_csv(tmp / "r2_by_n.csv", index=False)
        result.summary().to_csv(tmp / "summary.csv", index=False)
        (tmp / "replay.json").write_text(dumps(result.to_dict()))
        save_figure(plot_campaign(result).figure, tmp / "campaign.png")


def _add_instrument_options(p) -> None:
    p.add_argument("--gammas", nargs="+", type=ANGLES, action=Flatten, metavar="G",
                   help="the angles of incidence the instrument can set, degrees, space- or "
                        "comma-separated (<= 0, or magnitudes; default -10 -20 ... -70)")
    p.add_argument("--theta-min", type=ANGLE, default=-80.0,
                   help="lowest receiver angle (deg, default -80)")
    p.add_argument("--theta-max", type=ANGLE, default=80.0,
                   help="highest receiver angle (deg, default 80)")
    p.add_argument("--theta-step", type=POSITIVE, default=1.0,
                   help="the receiver's step: it stands at theta-min + k * step (deg, "
                        "default 1)")
    add_resolution_argument(p, "the readings are fitted as that average (the coefficients "
                               "are the material's), no two are closer than half of it, and "
                               "a lobe narrower than it is warned of")
    p.add_argument("--min-separation", type=NON_NEGATIVE, default=None,
                   help="two readings of one angle of incidence closer than this are the "
                        "same (deg, default half the step or half the resolution, whichever "
                        "is larger)")
    p.add_argument("--source-clearance", type=NON_NEGATIVE, default=5.0,
                   help="the receiver cannot stand within this many degrees of the source "
                        "direction theta = gamma (deg, default 5)")
    p.add_argument("--gamma-settings", type=POSITIVE_INT, default=None, metavar="K",
                   help="use at most K angles of incidence in the whole campaign (default: "
                        "any)")
    p.add_argument("--gamma-cost", type=NON_NEGATIVE, default=0.0, metavar="C",
                   help="cost of setting a new angle of incidence, in readings: a reading "
                        "that needs one counts 1 + C (default 0)")


def register(sub) -> None:
    p = sub.add_parser(
        "next", help="the next readings to take on a new material, and whether to stop",
        description="Propose the next K measurement settings (gamma, theta) for a material "
                    "from the readings taken so far (MEASURED.csv may hold only the header "
                    "gamma_deg,theta_deg,power: then the opening design), each with why, "
                    "and print the verdict: stop or continue. Angles in degrees; gamma "
                    "negative on the source side.")
    p.add_argument("measured", metavar="MEASURED.csv",
                   help="readings so far: gamma_deg, theta_deg, power[, sigma] (CSV or "
                        "Parquet; a header alone: nothing measured yet), in the order they "
                        "were taken: append new rows at the end (the campaign replays them "
                        "in that order, and its fits and verdict follow it)")
    p.add_argument("--n", type=POSITIVE_INT, default=1, metavar="K",
                   help="how many settings to propose (default 1)")
    p.add_argument("--out", metavar="NEXT.csv",
                   help="write the settings here (gamma_deg, theta_deg, why, new_gamma and "
                        "an empty power column; default: print only)")
    _add_instrument_options(p)
    add_model_argument(p)
    p.add_argument("--seed", type=SEED, default=0, help="seed of the fits (default 0)")
    p.add_argument("--average-duplicates", action="store_true",
                   help="average the power of repeated (gamma, theta) readings instead of "
                        "refusing them")
    p.add_argument("--save", metavar="MATERIAL.json",
                   help="write the campaign's fit of the readings as a material file (as "
                        "'irreflect fit --save' does; the readings weighted by the share of "
                        "the range each stands for, as the verdict judged them; default: none)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(handler=_cmd_next)

    p = sub.add_parser(
        "campaign", help="replay measurement campaigns against a dense table",
        description="Replay measurement campaigns against a dense table used as the "
                    "instrument: the adaptive campaign (irreflect next), the paper's "
                    "12-point protocol, the glossy-aware protocol, random readings and "
                    "select's best subsets (hindsight). Prints R^2 against all points by "
                    "number of readings for each, and the N from which each stays within "
                    "0.01 of the all-points fit.")
    p.add_argument("data", metavar="DENSE.csv",
                   help="dense measurement table (CSV or Parquet) used as the instrument")
    p.add_argument("--strategies", default="adaptive,paper,glossy,random,hindsight",
                   help="comma-separated strategies (default adaptive,paper,glossy,random,"
                        "hindsight)")
    p.add_argument("--n-max", type=int_at_least(9), default=25,
                   help="readings per replayed campaign (default 25)")
    p.add_argument("--method", choices=("nearest", "interpolate"), default="nearest",
                   help="a reading is the table's own point (nearest, within --tolerance) "
                        "or interpolated along theta every --theta-step (default nearest)")
    p.add_argument("--theta-step", type=POSITIVE, default=None,
                   help="with --method interpolate: the receiver step (deg, default 1)")
    p.add_argument("--tolerance", type=NON_NEGATIVE, default=0.5,
                   help="largest gap (deg) a reading may be from the table's nearest point "
                        "(default 0.5)")
    p.add_argument("--noise", type=NON_NEGATIVE, default=0.0,
                   help="relative power noise added to every reading, 1 sigma (default 0)")
    p.add_argument("--angle-error", type=NON_NEGATIVE, default=0.0,
                   help="receiver angle error, uniform +- this many degrees (default 0)")
    p.add_argument("--generations", type=POSITIVE_INT, default=None,
                   help="NSGA-II generations of the hindsight subsets (default 100)")
    add_resolution_argument(p, "the dense table was read with it: the campaign's "
                               "instrument has it and every fit but the hindsight subsets' "
                               "is the model averaged over it, as 'next --resolution' fits")
    add_model_argument(p)
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the fits, the noise and the random readings (default 0)")
    p.add_argument("--average-duplicates", action="store_true",
                   help="average the power of duplicated (gamma, theta) rows of DENSE")
    p.add_argument("--out", metavar="DIR",
                   help="write r2_by_n.csv, summary.csv, replay.json and campaign.png here "
                        "(default: print only)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(handler=_cmd_campaign)


def _save_notes(campaign, verdict, tool) -> str:
    """The notes of the material file ``next --save`` writes: which fit it holds."""
    what = ("the quadrature estimate: the model fitted to the instrument's range as the "
            "design's posterior pictures it between the readings" if campaign.estimated else
            "the readings weighted by the share of the instrument's range each stands for")
    blur = (f"; fitted as the model averaged over the receiver's {tool.resolution:g} deg "
            "resolution (the coefficients are the material's, as a point receiver would see "
            "it)" if tool.resolution else "")
    return f"adaptive campaign (irreflect next), {verdict.text}; {what}{blur}"
