"""``python -m estimators.calibration``: calibrate the Lidar mounts of a drive and print them.

Examples::

    python -m estimators.calibration --world hallway --trace zigzag --seed 0
    python -m estimators.calibration --bag drive.bag --guess -0.4 0.1 15
    python -m estimators.calibration --carmen robot.clf --guess -0.7 0 180
    python -m estimators.calibration --carmen left.log right.log
    python -m estimators.calibration --world hallway --trace loop --mount-error 0.03 0.04 3 \
        --compare pc_fusion lidar_odometry

``--tf-out mounts.yaml`` writes the mounts (Lidar 1 as configured, the others as calibrated)
as ``base_link -> lidar_k`` transforms and prints a ``static_transform_publisher`` command per
Lidar (:mod:`estimators.calibration.tf_output`).

A simulated drive (``--world``/``--trace``/``--seed``, ``--config`` JSON env overrides) is
recorded with the scripted driver; a ROS bag (``--bag``, ``--topics``) is read with
:func:`estimators.datasets.load_bag`; CARMEN logs (``--carmen``: one log's front and rear
laser, or two logs' front lasers, paired by stamp) with
:func:`estimators.datasets.carmen_pairs.carmen_recording`. ``--guess x y heading_deg`` (one
triple per Lidar 2..K, in Lidar 1's frame) starts the calibration; for a bag it replaces the
bag's tf mounts, for a CARMEN log the mounts its parameters state.
``--compare`` (simulated drives) scores estimators with the true mounts, with Lidar 2's mount
wrong by ``--mount-error dx dy dheading_deg``, and with the mounts self-calibrated from the
wrong ones (:func:`estimators.calibration.comparison.compare_mounts`).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Sequence

import numpy as np

from estimators.calibration.self_calibration import NoOverlapWarning, calibrate
from lidar_env.core import DualLidarError
from lidar_env.core.se2 import compose, relative


def _parser(prog: str = "python -m estimators.calibration") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Estimate Lidars 2..K's mounts from "
                                     "a drive.",
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--bag", help="ROS 1 .bag, ROS 2 .db3/.mcap file or bag directory")
    source.add_argument("--carmen", nargs="+", metavar="LOG",
                        help="a CARMEN log with FLASER + RLASER, or two logs of one laser each")
    source.add_argument("--world", help="simulate a drive in this world (with --trace)")
    parser.add_argument("--trace", default="zigzag", help="trace of the simulated drive")
    parser.add_argument("--seed", type=int, default=0, help="env seed of the simulated drive")
    parser.add_argument("--config", default="{}", help="env config overrides as JSON")
    parser.add_argument("--topics", nargs="+", help="LaserScan topics, Lidar 1 first")
    parser.add_argument("--guess", nargs="+", type=float, metavar="V",
                        help="x [m] y [m] heading [deg] of each of Lidars 2..K in Lidar 1")
    parser.add_argument("--estimator", default="lidar_odometry",
                        help="registered estimator for each Lidar's own odometry")
    parser.add_argument("--no-refine", action="store_true",
                        help="motion only: skip aligning overlapping scans")
    parser.add_argument("--compare", nargs="+", metavar="ESTIMATOR",
                        help="simulated drive: score these with true, wrong, calibrated mounts")
    parser.add_argument("--mount-error", nargs=3, type=float, default=(0.03, 0.04, 3.0),
                        metavar=("DX", "DY", "DEG"),
                        help="error of Lidar 2's configured mount for --compare [m m deg]")
    parser.add_argument("--tf-out", metavar="YAML",
                        help="write the mounts as base_link -> lidar_k transforms (YAML) and "
                             "print static_transform_publisher commands")
    return parser


def _compare(args: argparse.Namespace, recording) -> int:
    from estimators.calibration.comparison import compare_mounts, comparison_table

    dx, dy, degrees = args.mount_error
    results = compare_mounts(recording, (dx, dy, np.radians(degrees)), args.compare)
    print(comparison_table(results))
    mount = results["calibrated"]["_mount"]
    print(f"calibrated lidar_2 mount (car frame): x {mount['x']:+.4f} m, y {mount['y']:+.4f} m, "
          f"heading {np.degrees(mount['heading']):+.4f} deg; true "
          + ", ".join(f"{v:+.4f}" for v in recording.setup.mounts[1]))
    return 0


def _guess(values: Sequence[float] | None) -> np.ndarray | None:
    if values is None:
        return None
    if len(values) % 3:
        raise DualLidarError(f"--guess: expected triples x y heading_deg, got {len(values)} "
                             "numbers")
    rows = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    rows[:, 2] = np.radians(rows[:, 2])
    return rows


def _recording(args: argparse.Namespace, guess: np.ndarray | None):
    if args.bag:
        from estimators.datasets import load_bag

        mounts = None if guess is None else np.vstack([np.zeros(3), guess])
        return load_bag(args.bag, args.topics, mounts=mounts)
    if args.carmen:
        from estimators.datasets.carmen_pairs import carmen_recording

        return carmen_recording(args.carmen)  # --guess goes to calibrate() as for the others
    from estimators.leaderboard.recording import record
    from estimators.leaderboard.records import Scenario

    if args.seed < 0:
        raise DualLidarError(f"--seed: expected an integer >= 0, got {args.seed}")
    try:
        config = json.loads(args.config)
    except json.JSONDecodeError as error:
        raise DualLidarError(f"--config: expected env config overrides as a JSON object, "
                             f"got {args.config!r:.60} ({error.msg})") from None
    if not isinstance(config, dict):
        raise DualLidarError(f"--config: expected a JSON object of env config keys, got a "
                             f"{type(config).__name__}")
    return record(Scenario(args.world, args.trace, args.seed, config=config))


def _write_tf(path: str, recording, calibration) -> None:
    """Write the mounts (Lidar 1 as configured, the others as calibrated where observable) as
    a tf YAML and print the static_transform_publisher commands."""
    from estimators.calibration.tf_output import static_transform_commands, tf_yaml

    setup = recording.setup
    mounts, sources = [setup.mounts[0]], ["configured"]
    for estimate, configured in zip(calibration.mounts, setup.mounts[1:], strict=True):
        calibrated = not estimate.unobservable
        mounts.append(compose(setup.mounts[0], estimate.value) if calibrated else configured)
        sources.append("calibrated" if calibrated else "configured (unobservable)")
    frames = [sensor.frame for sensor in setup.sensors]
    with open(path, "w") as file:
        file.write(tf_yaml(mounts, frames, sources))
    print(f"tf: wrote {path}")
    for command in static_transform_commands(mounts, frames):
        print(f"  {command}")


def main(argv: Sequence[str] | None = None,
         prog: str = "python -m estimators.calibration") -> int:
    """Calibrate and print the mounts; ``prog`` names the command in usage lines (``duallidar
    calibrate``). Returns the exit status (2 for bad input)."""
    args = _parser(prog).parse_args(argv)
    try:
        guess = _guess(args.guess)
        recording = _recording(args, guess)
        if args.compare:
            if args.bag:
                raise DualLidarError("--compare: expected a simulated drive (--world), whose "
                                     "true poses score the runs; a bag has none")
            return _compare(args, recording)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", NoOverlapWarning)
            calibration = calibrate(recording, guess, estimator=args.estimator,
                                    refine=not args.no_refine)
    except (DualLidarError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    for warning in caught:
        print(f"warning: {warning.message}", file=sys.stderr)
    setup = recording.setup
    print(f"{len(recording.times)} scans of {setup.n_lidars} Lidars")
    for estimate, configured in zip(calibration.mounts, setup.mounts[1:], strict=True):
        print(estimate.describe())
        stated = relative(setup.mounts[0], configured)
        print(f"  configured: x {stated[0]:+.4f} m, y {stated[1]:+.4f} m, heading "
              f"{np.degrees(stated[2]):+.4f} deg")
        if not estimate.unobservable:
            car = compose(setup.mounts[0], estimate.value)
            print(f"  in the car frame (lidar_1 as configured): x {car[0]:+.4f} m, y "
                  f"{car[1]:+.4f} m, heading {np.degrees(car[2]):+.4f} deg")
    if args.tf_out:
        _write_tf(args.tf_out, recording, calibration)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
