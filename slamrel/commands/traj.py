"""``slamrel traj``: list a bag's topics, describe trajectories, convert between formats.

evo_traj's job for slamrel's readers: ``traj topics BAG`` lists a ROS bag's topics (which
hold trajectories), ``traj info TRAJ...`` prints poses, time span, duration, path length,
rate and frames, ``traj convert TRAJ -o OUT`` writes a trajectory as TUM, KITTI, CSV or
plain text through slamrel's writers. TRAJ is any trajectory slamrel reads, a bag topic
``BAG:TOPIC`` or tf chain ``BAG:/tf:PARENT.CHILD`` included.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from slamrel.constants import TRAJECTORY_FORMATS

HELP = "inspect and convert trajectories (bag topics, info, TUM/KITTI/CSV)"
#: Formats ``traj convert`` writes, and the output extensions that name one.
WRITE_FORMATS = ("tum", "kitti", "csv", "plain")
_EXTENSIONS = {".tum": "tum", ".csv": "csv", ".kitti": "kitti"}


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "traj",
        help=HELP,
        description=HELP + ". TRAJ is a trajectory file in any format slamrel reads, or a "
        "ROS bag topic BAG:TOPIC (BAG a ROS 1 .bag, ROS 2 .db3/.mcap or bag folder; needs the "
        "'bags' extra) or tf chain BAG:/tf:PARENT.CHILD.",
    )
    tsub = p.add_subparsers(dest="traj_command", metavar="ACTION")
    tsub.required = True

    t = tsub.add_parser(
        "topics",
        help="list the topics of a ROS bag",
        description="List a ROS bag's topics: name, message type, message count, and whether "
        "slamrel reads a trajectory from it (PoseStamped, PoseWithCovarianceStamped, "
        "Odometry, TransformStamped, TFMessage).",
    )
    t.add_argument("bag", metavar="BAG", help="ROS 1 .bag, ROS 2 .db3/.mcap file or bag folder")
    t.add_argument("--json", metavar="FILE", help="also write the list as JSON")
    t.set_defaults(func=run_topics)

    i = tsub.add_parser(
        "info",
        help="poses, time span, length, rate and frames of trajectories",
        description="Print, for each TRAJ: poses, dimension, first and last time, duration, "
        "path length, mean rate, median and largest time step, position extent, and for a "
        "bag topic its message type and frames.",
    )
    i.add_argument("trajectories", nargs="+", metavar="TRAJ", help="trajectories to describe")
    _read_arguments(i)
    i.add_argument("--json", metavar="FILE", help="also write the information as JSON")
    i.set_defaults(func=run_info)

    c = tsub.add_parser(
        "convert",
        help="write a trajectory as TUM, KITTI, CSV or plain text",
        description="Read TRAJ and write it in another format, every pose at 17 significant "
        "digits (read back bit for bit). 3-D trajectories are written as TUM or KITTI (CSV "
        "and plain are planar formats: pass --planar to project).",
    )
    c.add_argument("trajectory", metavar="TRAJ", help="the trajectory to convert")
    c.add_argument("-o", "--output", required=True, metavar="OUT", help="the file written")
    c.add_argument(
        "--to",
        choices=WRITE_FORMATS,
        help="output format (default: from OUT's extension: .tum, .kitti, .csv)",
    )
    c.add_argument(
        "--output-times",
        metavar="FILE",
        help="KITTI output: also write the timestamps, one a line (KITTI's times.txt)",
    )
    _read_arguments(c)
    c.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    c.set_defaults(func=run_convert)


def _read_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--format", choices=TRAJECTORY_FORMATS, help="format of TRAJ (default: recognised)"
    )
    p.add_argument("--times", metavar="FILE", help="KITTI TRAJ: timestamps, one a line")
    p.add_argument(
        "--planar",
        action="store_true",
        help="read 3-D trajectories in 2-D (z, roll and pitch discarded, with a warning)",
    )


def run_topics(args: argparse.Namespace) -> int:
    """``slamrel traj topics BAG``."""
    from relation_metric.errors import InputError
    from slamrel.commands.common import check_outputs
    from slamrel.formats.bags import bag_topics, is_bag

    check_outputs([args.json], [args.bag])
    if not is_bag(args.bag):
        raise InputError(
            "not a ROS bag: expected a .bag, .db3 or .mcap file or a ROS 2 bag folder "
            "(with metadata.yaml)",
            path=args.bag,
        )
    topics = bag_topics(args.bag)
    if args.json:
        from slamrel.formats.results import write_json

        rows = [
            {
                "topic": t.topic,
                "type": t.msgtype,
                "messages": t.count,
                "trajectory": t.is_trajectory,
                "read_as": t.read_as,
            }
            for t in topics
        ]
        write_json(args.json, {"bag": args.bag, "topics": rows})
    width = max([len(t.topic) for t in topics] + [5])
    tw = max([len(t.msgtype) for t in topics] + [4])
    print(f"{'topic':<{width}}  {'type':<{tw}}  {'messages':>8}  slamrel reads")
    for t in topics:
        use = {"trajectory": "trajectory", "laser scans": "laser scans (relations align)"}
        reads = use.get(t.read_as or "", "-")
        print(f"{t.topic:<{width}}  {t.msgtype:<{tw}}  {t.count:>8d}  {reads}")
    return 0


def run_info(args: argparse.Namespace) -> int:
    """``slamrel traj info TRAJ...``."""
    import warnings

    from relation_metric.timeorder import RepeatedTimeWarning
    from slamrel.commands.common import check_outputs, input_files
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.bags import read_bag_poses, split_bag_spec
    from slamrel.trajinfo import trajectory_info

    check_outputs([args.json], input_files(list(args.trajectories)))
    report = []
    for path in args.trajectories:
        with warnings.catch_warnings():  # repeats are described below, not warned about
            warnings.simplefilter("ignore", RepeatedTimeWarning)
            loaded = load_trajectory(
                path, args.format, planar=args.planar, times=args.times, repeats="keep"
            )
        info = trajectory_info(loaded.trajectory)
        entry: dict[str, object] = {"trajectory": path, "format": loaded.format, **info.as_dict()}
        if loaded.format == "kitti" and args.times is None:
            entry.update(start_s=None, end_s=None, duration_s=None, rate_hz=None)
            entry.update(median_step_s=None, max_gap_s=None, times=False)
        entry["repeated_times"] = loaded.repeated.as_dict()
        spec = split_bag_spec(path)
        if spec is not None:
            with warnings.catch_warnings():  # read once above: its warnings were said
                warnings.simplefilter("ignore")
                got = read_bag_poses(spec)
            entry.update(
                message_type=got.msgtype,
                frame_id=got.frame_id,
                child_frame_id=got.child_frame_id,
                covariance=got.covariances is not None,
            )
        if loaded.skipped:
            entry["skipped"] = dict(loaded.skipped)
        entry["out_of_order"] = loaded.out_of_order
        report.append(entry)
        print(_info_text(path, entry))
    if args.json:
        from slamrel.formats.results import write_json

        write_json(args.json, {"trajectories": report})
    return 0


def _info_text(path: str, e: dict[str, object]) -> str:
    def num(key: str, unit: str, fmt: str = ".6g") -> str:
        v = e[key]
        return "n/a" if v is None else f"{v:{fmt}} {unit}"

    ext = " × ".join(f"{v:.6g}" for v in e["extent_m"])  # type: ignore[attr-defined]
    if e.get("times", True):
        time = (
            f"  time         {e['start_s']:.6f} .. {e['end_s']:.6f} s "
            f"(duration {e['duration_s']:.6g} s)"
        )
        rate = (
            f"  rate         {num('rate_hz', 'Hz')} (median step {num('median_step_s', 's')}, "
            f"largest gap {num('max_gap_s', 's')})"
        )
    else:
        time = f"  time         no times, {e['poses']} poses (KITTI: --times FILE gives them)"
        rate = "  rate         n/a (no times)"
    lines = [
        f"{path}",
        f"  format       {e['format']}, {e['dimension']}, {e['poses']} poses",
        time,
        f"  length       {num('length_m', 'm')}; extent {ext} m",
        rate,
    ]
    rep: Any = e["repeated_times"]
    if rep["count"]:
        lines.append(
            f"  repeats      {rep['count']} pose(s) repeat the previous pose's timestamp, "
            f"{rep['differing']} with a different pose (first at line {rep['first_line']}):\n"
            "               a reference keeps the first of each; an estimate with different "
            "poses is refused\n               ('slamrel ape|rpe --duplicate_stamps keep' "
            "keeps them all, as evo)"
        )
    if "message_type" in e:
        child = f" -> {e['child_frame_id']}" if e["child_frame_id"] else ""
        cov = ", with covariance" if e["covariance"] else ""
        lines.append(
            f"  messages     {e['message_type']}; frame {e['frame_id'] or '(none)'}{child}{cov}"
        )
    if e.get("skipped"):
        lines.append(f"  skipped      {e['skipped']}")
    if e["out_of_order"]:
        lines.append(f"  time order   {e['out_of_order']} pose(s) out of time order (sorted)")
    return "\n".join(lines)


def run_convert(args: argparse.Namespace) -> int:
    """``slamrel traj convert TRAJ -o OUT``."""
    from relation_metric.errors import OptionError
    from slamrel.commands.common import check_outputs, input_files
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.text import NUMBER_FORMAT, write_text_atomic
    from slamrel.formats.trajectories import write_trajectory

    fmt = args.to or _EXTENSIONS.get(os.path.splitext(args.output)[1].lower())
    if fmt is None:
        raise OptionError(
            f"cannot tell the output format from {args.output!r}; pass --to "
            f"({', '.join(WRITE_FORMATS)}) or name it .tum, .kitti or .csv",
            option="--to",
        )
    if args.output_times and fmt != "kitti":
        raise OptionError("is for a KITTI output (--to kitti)", option="--output-times")
    check_outputs([args.output, args.output_times], input_files([args.trajectory, args.times]))
    loaded = load_trajectory(
        args.trajectory, args.format, role="estimate", planar=args.planar, times=args.times
    )
    traj = loaded.trajectory
    if traj.group.name == "SE3" and fmt in ("csv", "plain"):
        raise OptionError(
            f"{args.trajectory} is 3-D; {fmt} holds planar poses: convert to tum or kitti, or "
            "pass --planar to project onto the plane",
            option="--to",
        )
    write_trajectory(args.output, traj, format=fmt)
    if args.output_times:
        t = traj.timestamps
        write_text_atomic(args.output_times, (NUMBER_FORMAT + "\n") * t.size % tuple(t.tolist()))
    if not args.quiet:
        dim = "3-D" if traj.group.name == "SE3" else "2-D"
        times = f" (+ times {args.output_times})" if args.output_times else ""
        print(f"{len(traj)} {dim} poses ({loaded.format}) -> {args.output} ({fmt}){times}")
    return 0
