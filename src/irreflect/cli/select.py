"""``irreflect select``: which measurements to take (Pareto frontier, knee, best 12 points).

One DATA file and one seed write straight into ``--out DIR``
(:data:`irreflect.plots.selection.OUTPUT_FILES`)::

    DIR/pareto.csv           n_points, one_minus_r2, r2, points ("(gamma,theta);...", degrees)
    DIR/optimal_points.csv   gamma_deg, theta_deg of the best 12-point subset
    DIR/summary.json         knee_n, enough_points, methods A/B/12, evaluations, seconds, ...
    DIR/pareto.png           the frontier with the ideal point, the knee, "enough points"
                             and the best 12 points (Fig. 18)
    DIR/optimal_points.png   the chosen points in the (gamma, theta) plane (Fig. 19)

Several DATA files and/or ``--seeds`` run in parallel (local processes, or a Dask cluster
with ``--scheduler``) and write one such folder per run, ``DIR/<name>/seed<S>/``, plus
``DIR/runs.csv`` and ``DIR/summary.json`` over all runs. Everything appears atomically.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from .options import (
    POSITIVE_INT,
    SEED,
    add_data_argument,
    add_ignore_sigma_argument,
    add_model_argument,
    int_at_least,
    load_data,
    warn_if_sigma_decides,
)

PAPER_N = 12  # the paper's protocol size (irreflect.selection.run.PAPER_N)


def _print_run(result, methods: dict | None) -> None:
    m = result.measurements
    state = " (interrupted: results so far)" if result.interrupted else ""
    cfg = result.settings
    limit = (f"at most {cfg['max_points']} points"
             if cfg.get("max_points") and cfg["max_points"] < m.n_points else "all points")
    print(f"{m.name}: {m.n_points} points, selector {result.selector}, population "
          f"{cfg.get('pop_size')}, {cfg.get('generations')} generations, {limit}, seed "
          f"{result.seed}{state}")
    print(f"  {result.evaluations} subset fits ({result.failed_fits} failed) in "
          f"{result.seconds:.1f} s, {result.fits_per_second:.0f} fits/s; "
          f"hypervolume {result.hypervolume:.5f}")
    front = result.front
    enough = result.enough
    last = max(result.knee_n, PAPER_N,
               ((enough.n_high or enough.n or 0) if enough is not None else 0))
    shown = front[front["n_points"] <= last + 3]
    more = len(front) - len(shown)
    print("  frontier: " + ", ".join(f"N={int(r.n_points)}: R2={r.r2:.5f}"
                                     for r in shown.itertuples())
          + (f" ... ({more} more up to N={int(front['n_points'].max())}, in pareto.csv)"
             if more else ""))
    summary = result.front_summary
    if summary is not None:
        print(f"  knee: N = {result.knee_n} (closest to the ideal point with N scaled over "
              f"{summary.n_min}..{summary.n_total} and 1 - R^2 over {summary.reference:.4g}..1; "
              f"frontier completed for every N up to {summary.completed_up_to}, "
              f"{summary.completion_fits} extra fits)")
    else:
        print(f"  knee: N = {result.knee_n}")
    if enough is not None:
        spread = ("" if enough.sigma_low == enough.sigma_high else
                  f", 68 % interval {enough.sigma_low:.3g}-{enough.sigma_high:.3g}")
        print(f"  enough points: {enough.range_text()}: the fewest whose fit's RMSE on all "
              f"points is within the noise sigma = {enough.sigma:.4g} ({enough.noise}"
              f"{spread}) of the all-points fit's {enough.rmse_all:.4g}")
    elif summary is not None and summary.enough_note:
        print(f"  {summary.enough_note}")
    if methods is not None:
        parts = []
        for key in ("A", "B", "12"):
            r2 = methods[key]["r2"]
            parts.append(f"{key}: R2={r2:.5f} ({methods[key]['n_points']} points)"
                         if r2 is not None else f"{key}: n/a")
        print("  methods: " + "; ".join(parts) + f"  [{methods['note']}]")
        if methods["12"].get("how"):
            print(f"  method 12: {methods['12']['how']}")
        _warn_b_below_12(m.name, methods)
        if methods["12"]["r2"] is not None and methods["A"]["r2"] is not None:
            _print_protocol_verdict(result, methods)


def _warn_b_below_12(name: str, methods: dict) -> None:
    """A warning when the file named optimal is not: the best 12 points, fitted thoroughly,
    more than 0.01 below the paper's 12 points (a held-out noisy matte table: R^2 -235.6
    against the paper's 0.8828; the benchmark's "no bound" margin)."""
    from ..campaign.replay import NO_BOUND_MARGIN

    r2_b, r2_12 = methods["B"]["r2"], methods["12"]["r2"]
    if r2_b is None or r2_12 is None or not r2_b < r2_12 - NO_BOUND_MARGIN:
        return
    print(f"irreflect: warning: {name}: optimal_points.csv holds the search's best "
          f"{PAPER_N} points, but fitted thoroughly they give R^2 {r2_b:.4g} against all "
          f"points, below the paper's {PAPER_N} points' {r2_12:.4g}: do not measure them as "
          "a protocol (the methods line says why)", file=sys.stderr)


def _print_protocol_verdict(result, methods: dict) -> None:
    """The paper's protocol's verdict (the rule of evaluate-protocol and the report, on
    Method 12's snapped points) on stdout, and a warning with its causes and remedies on
    stderr when it does not pass."""
    from ..protocol.advice import adaptive_remedy
    from ..protocol.points import assess_subset

    m = result.measurements
    summary = result.front_summary
    reference = summary.reference_fit if summary is not None else None
    verdict = assess_subset(m, reference=reference, model=result.model, seed=result.seed)
    print("  " + verdict.line().replace("verdict: ", "verdict on method 12: ", 1))
    if verdict.passed:
        for c in verdict.causes:  # a pass against a curve that misses the material
            print(f"irreflect: warning: {m.name}: the paper's 12-point protocol passes, but "
                  f"{c.text}; remedy: {c.remedy}", file=sys.stderr)
        return
    r2_12, r2_b, r2_a = methods["12"]["r2"], methods["B"]["r2"], methods["A"]["r2"]
    worse = ", worse than a constant" if r2_12 < 0 else ""
    best = "" if r2_b is None else f"; the best 12 points give {r2_b:.4g}"
    word = "fails" if verdict.failed else "is marginal"
    causes = "; ".join(c.text for c in verdict.causes)
    specific = [c.remedy for c in verdict.causes if c.remedy]
    print(f"irreflect: warning: {m.name}: the paper's 12-point protocol {word} on this "
          f"material: R^2 = {r2_12:.4g} against all points{worse} (the all-points fit's "
          f"{r2_a:.4g}{best}); cause: {causes}; remedy: "
          + "".join(f"{r}; " for r in specific)
          + ("measure the points in optimal_points.csv (the best 12 points for this "
             "material), or " if r2_b is not None and r2_b > r2_12 else "")
          + adaptive_remedy(m), file=sys.stderr)


def _cmd_select(args) -> int:
    from .._atomic import claim_output
    from ..errors import IrreflectError
    from ..models import get_model
    from ..selection.parallel import check_scheduler_address
    from ..selection.selectors import get_selector
    from ..validation import check_search_budget, check_selection_budget, short_list

    # everything that can be checked before any work: names, seeds, the scheduler's
    # address, output and checkpoint paths (claimed: checked and locked), table sizes
    get_selector(args.selector)
    get_model(args.model)
    seeds = args.seeds if args.seeds else [args.seed]
    if len(set(seeds)) != len(seeds):
        raise IrreflectError(f"--seeds must be distinct; found {short_list(seeds)}")
    if args.scheduler is not None:
        check_scheduler_address(args.scheduler)
    flat = len(args.data) == 1 and len(seeds) == 1
    if not str(args.out).strip():  # Path("") would be the current folder
        raise IrreflectError("--out must name a folder; found an empty name")
    out = Path(args.out)
    with contextlib.ExitStack() as stack:
        stack.enter_context(claim_output(out, "dir", "--out"))
        if args.checkpoint is not None:
            kind = "file" if flat and args.scheduler is None else "checkpoint-dir"
            stack.enter_context(claim_output(args.checkpoint, kind, "--checkpoint"))
        tables = []
        for path in args.data:
            meas = load_data(args, "select", path)
            check_selection_budget(meas.n_points, args.max_points, str(path))
            check_search_budget(args.pop_size, args.generations, meas.n_points,
                                pop_option="--pop-size", gen_option="--generations")
            # a fit: after the budgets, which refuse before any work
            warn_if_sigma_decides(meas, args.model, "select scores every subset against it")
            if args.max_points is not None and args.max_points > meas.n_points:
                # the search clamps it (run_selection): said before the work, not hidden
                # behind the run line's "all points"
                n = meas.n_points
                print(f"irreflect: warning: {meas.name}: --max-points {args.max_points} "
                      f"exceeds the table's {n} points: subsets of up to all {n} points are "
                      f"searched (as with --max-points {n})", file=sys.stderr)
            tables.append(meas)
        return _run_and_write(args, tables, seeds, out, flat)


def _run_and_write(args, tables, seeds, out: Path, flat: bool) -> int:
    import pandas as pd

    from .._atomic import atomic_directory
    from .._jsonio import dumps
    from ..errors import IrreflectError
    from ..plots.selection import OUTPUT_FILES, write_outputs
    from ..selection.parallel import run_many
    from ..selection.run import compare_methods, run_selection

    kwargs = dict(model=args.model, selector=args.selector, pop_size=args.pop_size,
                  generations=args.generations, max_points=args.max_points,
                  checkpoint_every=args.checkpoint_every)
    if flat and args.scheduler is None:
        res = run_selection(tables[0], seed=seeds[0], progress=not args.quiet,
                            checkpoint=args.checkpoint, **kwargs)
        methods = compare_methods(tables[0], res, model=args.model, seed=seeds[0])
        outcomes, interrupted = [(tables[0].name, res, methods)], res.interrupted
    else:
        runs, interrupted = run_many(tables, seeds, scheduler=args.scheduler,
                                     workers=args.workers, progress=not args.quiet,
                                     checkpoint_dir=args.checkpoint, **kwargs)
        if not runs:
            raise IrreflectError("interrupted before any run finished: nothing written")
        outcomes = [(o.dataset, o.result, o.methods) for o in runs]
    if flat:
        _, res, methods = outcomes[0]
        with atomic_directory(out, command="select") as tmp:
            write_outputs(res, methods, tmp)
        _print_run(res, methods)
        print(f"wrote {out}/{', '.join(OUTPUT_FILES)}")
        return 130 if interrupted else 0
    rows, summaries = [], []
    with atomic_directory(out, command="select") as tmp:
        for dataset, res, methods in outcomes:
            write_outputs(res, methods, tmp / dataset / f"seed{res.seed}")
            summaries.append(res.summary(methods))
            e = res.enough
            row = {"dataset": dataset, "seed": res.seed, "knee_n": res.knee_n,
                   "enough_n": None if e is None else e.n,
                   "enough_n_low": None if e is None else e.n_low,
                   "enough_n_high": None if e is None else e.n_high,
                   f"r2_at_{PAPER_N}": 1 - res.best_score(PAPER_N),
                   "hypervolume": res.hypervolume, "evaluations": res.evaluations,
                   "failed_fits": res.failed_fits, "seconds": round(res.seconds, 2),
                   "interrupted": res.interrupted}
            if methods is not None:
                for k in ("A", "B", "12"):
                    row[f"r2_{k}"] = methods[k]["r2"]
            rows.append(row)
        pd.DataFrame(rows).to_csv(tmp / "runs.csv", index=False)
        (tmp / "summary.json").write_text(dumps({"runs": summaries, "interrupted": interrupted}))
    for _, res, methods in outcomes:
        _print_run(res, methods)
    print(f"wrote {len(outcomes)} run folder(s), {out}/runs.csv and {out}/summary.json")
    return 130 if interrupted else 0


def register(sub) -> None:
    from ..selection.selectors import SELECTORS

    p = sub.add_parser(
        "select",
        help="choose which few measurements to take (Pareto frontier, knee, best 12 points)",
        description="Search subsets of a dense measurement set for the fewest points whose "
                    "fit still describes all points (NSGA-II by default, the paper's Fig. 18), "
                    "and compare Method A (all points), B (best 12) and 12 (the paper's "
                    "protocol, Table 1).",
    )
    add_data_argument(p, nargs="+")
    add_model_argument(p)
    add_ignore_sigma_argument(p)
    p.add_argument("--selector", default="nsga2",
                   help=f"search strategy: {', '.join(SELECTORS)} (default nsga2)")
    p.add_argument("--pop-size", type=int_at_least(2), default=100,
                   help="population (default 100)")
    p.add_argument("--generations", type=POSITIVE_INT, default=200,
                   help="generations (default 200); other selectors spend pop-size x "
                        "generations fits")
    p.add_argument("--seed", type=SEED, default=0, help="seed (default 0)")
    p.add_argument("--seeds", type=SEED, nargs="+", metavar="S",
                   help="several seeds: one run per DATA and seed (default: --seed only)")
    p.add_argument("--max-points", type=POSITIVE_INT, default=None,
                   help="largest number of points considered (default: all)")
    p.add_argument("--checkpoint", metavar="FILE",
                   help="save the search every few generations and resume from it if it "
                        "exists (with several runs or --scheduler: a folder of per-run files; "
                        "default: no checkpoints)")
    p.add_argument("--checkpoint-every", type=POSITIVE_INT, default=10, metavar="G",
                   help="generations between checkpoints (default 10)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="dask.distributed scheduler (e.g. tcp://host:8786) for the runs "
                        "(default: local processes)")
    p.add_argument("--workers", type=POSITIVE_INT, default=None,
                   help="local worker processes for several runs, one library thread each "
                        "(default: one per core, at most one per run)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress display (a bar on a terminal, one line per stage through "
                        "a pipe)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(handler=_cmd_select)
