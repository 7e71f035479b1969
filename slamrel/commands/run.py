"""``slamrel run``: the main job end to end, with a self-contained report."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from relation_metric.errors import InputError, OptionError
from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_association_arguments,
    add_force_argument,
    add_iterations_argument,
    add_recovery_arguments,
    association_choice,
    association_file,
    check_iterations,
    check_outputs,
    check_rate,
    errors_about,
    in_option_words,
)
from slamrel.constants import NOISE_HELP, NOISE_NAMES, WORLDS

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    from landmark_graph.landmark_association import Association
    from slamrel.pipeline import RunInput


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "run",
        help="simulate, run EKF-SLAM, recover and score the trajectory, write a report",
        description="SOURCE is a SLAM result bundle directory (scored against its "
        "groundtruth.csv when it has one; without, the report holds what needs no truth and "
        "the scores on --relations) or a built-in world (" + ", ".join(WORLDS) + "); default "
        "simple1.",
    )
    p.add_argument(
        "source",
        nargs="?",
        default="simple1",
        metavar="SOURCE",
        help="a built-in world name or a SLAM result bundle directory (default: %(default)s)",
    )
    p.add_argument(
        "-o",
        "--output",
        default="slamrel-report",
        metavar="DIR",
        help="report directory (default: %(default)s)",
    )
    # simulated worlds only (refused with a bundle): None = not given, SIMULATION_DEFAULTS
    p.add_argument(
        "--noise", choices=NOISE_NAMES, default=None, help=NOISE_HELP + " (simulated worlds only)"
    )
    p.add_argument(
        "--seed",
        type=opt.seed,
        default=None,
        help="seed of the simulation and of the global relations' draw (with a bundle only "
        "the draw, and the run says so; default: 0)",
    )
    p.add_argument(
        "--rate",
        type=opt.nonnegative_int,
        default=None,
        help="control steps per measurement step (0: odometry; simulated worlds only; default: 0)",
    )
    p.add_argument(
        "--corrupt",
        type=opt.fraction,
        default=None,
        help="fraction of associations corrupted (simulated worlds only; default: 0)",
    )
    p.add_argument(
        "--noise-scale",
        type=opt.noise_scale,
        default=None,
        help="factor on the noise the filter assumes (simulated worlds only; default: 1)",
    )
    p.add_argument(
        "--skip-invalid-measurements",
        action="store_true",
        help="with a bundle: drop (and count) measurements with a range <= 0 or a non-finite "
        "range or bearing instead of refusing the bundle",
    )
    p.add_argument(
        "--jacobians",
        choices=("standard", "fej", "oc"),
        default="standard",
        help="where the EKF-SLAM evaluates its Jacobians: standard (the latest estimates), fej "
        "(first estimates, Huang et al. 2008) or oc (observability-constrained: the heading "
        "columns at points that keep the rotation unobservable, the rest at the latest "
        "estimates); fej and oc keep the unobservable directions, so the filter does not "
        "become overconfident (known associations) (WORLD only; default: "
        "%(default)s)",
    )
    p.add_argument(
        "--relations",
        metavar="FILE",
        help="reference relations (Freiburg .relations, e.g. from slamrel relations align) "
        "every estimate is scored on too, as slamrel evaluate scores them; with ground truth "
        "or without",
    )
    p.add_argument(
        "--reference-map",
        metavar="FILE",
        help="a reference landmark map (any format map-compare reads) the SLAM map is "
        "compared with, for a bundle without landmarks_groundtruth.csv",
    )
    add_iterations_argument(p, where=" (WORLD only)")
    add_association_arguments(p)
    add_force_argument(p)
    add_recovery_arguments(
        p,
        fail_help="exit 3 when the recovery diverges (the report is still written, with dead "
        "reckoning)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from slamrel.pipeline import read_run_input, run_pipeline, simulate_run_input, write_report

    if args.source not in WORLDS and not Path(args.source).is_dir():
        raise InputError(
            f"unknown SOURCE {args.source!r}; expected a SLAM result bundle directory or one of "
            f"{', '.join(WORLDS)}"
        )
    is_dir = Path(args.source).is_dir()
    _simulation_options(args, is_dir)
    if not is_dir:
        check_rate(args.source, args.rate)
    else:  # a bundle's map was made already: nothing to apply
        for name, value, plain in (
            ("--jacobians", args.jacobians, "standard"),
            ("--iterations", args.iterations, 1),
        ):
            if value != plain:
                raise OptionError(
                    "applies to a built-in WORLD (the reference EKF-SLAM run here), not to a "
                    f"bundle whose map was made already; run slamrel slam {name} on its log "
                    "instead",
                    option=name,
                )
    check_iterations(args)
    assoc_file = association_file(args.associate)
    check_outputs(
        [],
        [args.source if is_dir else None, assoc_file, args.relations, args.reference_map],
        dirs=[args.output],
        force=args.force,
    )
    start = time.perf_counter()
    if is_dir:
        from slamrel.formats.bundle import SKIP_INVALID_OPTION

        with in_option_words({SKIP_INVALID_OPTION: "--skip-invalid-measurements"}):
            inp = read_run_input(
                args.source, skip_invalid_measurements=args.skip_invalid_measurements
            )
    else:
        inp = simulate_run_input(
            args.source, noise=args.noise, seed=args.seed, rate=args.rate,
            corrupt_fraction=args.corrupt, noise_scale=args.noise_scale,
            jacobians=args.jacobians, iterations=args.iterations,
        )  # fmt: skip
    inp = _with_references(inp, args.relations, args.reference_map)
    associate = _association(args.associate, inp, assoc_file)
    words = {'associate="auto"': "--associate auto", "align=False": "--no-align"}
    with in_option_words(words):
        result = run_pipeline(
            inp, seed=args.seed, max_outlier_run=args.max_outlier_run or None,
            robust=args.robust, on_divergence="raise" if args.fail_on_divergence else "reenter",
            associate=associate, align=args.align, map_prior=args.map_prior,
        )  # fmt: skip
    html = write_report(result, args.output, force=args.force)
    if not args.quiet:
        print(f"slamrel run {result.name} ({time.perf_counter() - start:.1f} s)")
        if result.evaluations or result.reference is not None:
            head = f"{'relations':>13s}{'trans mean [m]':>16s}{'rot mean [rad]':>16s}"
            print(f"{'estimate':16s}{head}")
        for name, evs in result.evaluations.items():
            for set_name in ("consecutive", "loops", "global"):
                if set_name in evs:
                    ev = evs[set_name]
                    print(
                        f"{name:16s}{set_name:>13s}{ev.translation.abs.mean:16.4f}{ev.rotation.abs.mean:16.4f}"
                    )
        if result.reference is not None:
            for name, ev in result.reference.scores.items():
                t, r = ev.translation.abs.mean, ev.rotation.abs.mean
                print(f"{name:16s}{'reference':>13s}{t:16.4f}{r:16.4f}")
        if not result.has_truth:
            scored = "nothing scored" if result.reference is None else "scored only on --relations"
            print(f"no ground truth: {scored}; NEES not judged (see the report)")
        ms = result.map_summary
        if ms is not None:
            extra = f", {ms.unobserved} never within reach" if ms.unobserved else ""
            print(
                f"map: {ms.matched} landmarks matched {ms.association}, {ms.missed} missed"
                f"{extra}, {ms.spurious} spurious; OSPA {ms.ospa:.4f} m (c = {ms.cutoff:g}; "
                f"{ms.frame})"
            )
        a = result.agreement
        if a is not None and a.stretches:
            print(
                f"map and log DISAGREE on {len(a.stretches)} stretch(es), "
                f"{100 * a.fraction_of_log:.1f}% of the log (see the report)"
            )
        print(f"report: {html}")
    if result.recovery_error is not None:
        raise InputError(
            f"no trajectory recovered ({result.recovery_error}); report with dead reckoning "
            f"written to {html}"
        )
    return 0


#: The options of a simulated world and their defaults; with a bundle they are refused.
SIMULATION_DEFAULTS = {"noise": "a", "rate": 0, "corrupt": 0.0, "noise_scale": 1.0}


def _simulation_options(args: argparse.Namespace, is_dir: bool) -> None:
    """Fill the simulation options' defaults; with a bundle refuse the ones given (exit 2),
    refuse ``--skip-invalid-measurements`` with a world, and say what ``--seed`` changes."""
    given = [k for k in SIMULATION_DEFAULTS if getattr(args, k) is not None]
    if is_dir and given:
        names = ", ".join("--" + k.replace("_", "-") for k in given)
        raise OptionError(
            f"only a simulated world takes {names}; a bundle brings its own log and noise "
            f"(drop {names})",
            option="--" + given[0].replace("_", "-"),
        )
    if not is_dir and args.skip_invalid_measurements:
        raise OptionError(
            "applies to a bundle only (a simulated world has no invalid measurements)",
            option="--skip-invalid-measurements",
        )
    for k, default in SIMULATION_DEFAULTS.items():
        if getattr(args, k) is None:
            setattr(args, k, default)
    if is_dir and args.seed is not None and not args.quiet:
        print(
            f"note: --seed {args.seed} draws other global relations than the default seed 0 "
            "(the bundle's log and the recovery do not depend on it)"
        )
    if args.seed is None:
        args.seed = 0


def _with_references(inp: RunInput, relations: str | None, reference_map: str | None) -> RunInput:
    """The run's input with ``--relations`` (read as ``slamrel evaluate`` reads a
    ``.relations`` file) and ``--reference-map`` (read as ``map-compare`` reads a map)."""
    import dataclasses

    if reference_map is not None and inp.bundle.landmarks_groundtruth is not None:
        raise OptionError(
            "the bundle has its own landmarks_groundtruth.csv, which the map is compared "
            "with; drop --reference-map (or the file)",
            option="--reference-map",
        )
    changes: dict[str, Any] = {}
    if relations is not None:
        from slamrel.evaluation import EvaluateOptions, load_reference

        rel, trajectory = load_reference(relations, EvaluateOptions())
        if trajectory is not None:
            raise InputError(
                "read as a trajectory: expected a Freiburg .relations file (a ground-truth "
                "trajectory belongs in the bundle as groundtruth.csv)",
                path=relations,
            )
        changes |= {"reference_relations": rel, "reference_relations_name": relations}
    if reference_map is not None:
        from slamrel.formats.landmark_maps import read_map

        changes["reference_map"] = read_map(reference_map)
    return dataclasses.replace(inp, **changes) if changes else inp


def _association(value: str, inp: RunInput, path: str | None) -> str | Association:
    """``--associate`` for the run: the mode, or the file read against the bundle's maps (the
    SLAM map and the true landmarks, or the ``--reference-map``)."""
    if path is None:
        return value
    from landmark_graph.maps import LandmarkMap

    bundle = inp.bundle
    ref = inp.reference_map
    if ref is None and bundle.landmarks_groundtruth is not None:
        ref = LandmarkMap(*bundle.landmarks_groundtruth)
    if ref is None:
        raise InputError(
            "the bundle has no landmarks_groundtruth.csv (and no --reference-map is given): an "
            "association file has nothing to pair the map with",
            path=path,
        )
    est = LandmarkMap(bundle.map_ids, bundle.map_xy)
    with errors_about(path):
        choice = association_choice(value, est, ref)
    return choice
