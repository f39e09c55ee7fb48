"""Extrinsic self-calibration accuracy on simulated drives with turns.

For every world and trace, the scripted driver records a drive at 1 cm range noise; the
calibration sees only the scans and starts from a guess 0.3 m and 20 degrees off the true pose
of Lidar 2 in Lidar 1's frame. Printed per case: the error of the hand-eye (motion only) and
of the final (scan-aligned) mount, its stated 1-sigma, and the CPU time of the calibration
against the CPU time of one ``lidar_odometry`` run over the same drive with both Lidars (the
reference, measured in the same run; the calibration runs each Lidar's odometry once, then the
hand-eye solve and the alignment).

Layouts: ``360`` the env's two 360-degree Lidars 0.5 m apart on the car's axis; ``corner270``
two 270-degree Lidars on opposite corners facing outwards (needs the env's per-Lidar ``fov``).

Targets: mount error <= 1 cm and <= 0.2 degrees on every case.

    python benchmarks/bench_calibration.py [--worlds hallway random] [--traces zigzag loop]
        [--layouts 360 corner270] [--seed 0]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from estimators.calibration import calibrate
from estimators.leaderboard.recording import record, replay
from estimators.leaderboard.records import Scenario
from lidar_env.core.se2 import relative, wrap_angle

LAYOUTS = {
    "360": {},
    "corner270": {"lidars": [
        {"mount": [0.35, 0.2, np.pi / 4], "fov": 1.5 * np.pi, "n_beams": 270},
        {"mount": [-0.35, -0.2, -0.75 * np.pi], "fov": 1.5 * np.pi, "n_beams": 270}]},
}


def _errors(value: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Position error [mm] and heading error [deg]."""
    error = value - truth
    return 1e3 * float(np.hypot(error[0], error[1])), float(np.degrees(abs(wrap_angle(error[2]))))


def run_case(world: str, trace: str, layout: str, seed: int) -> str:
    dataset = record(Scenario(world, trace, seed, config=LAYOUTS[layout]))
    truth = relative(dataset.setup.mounts[0], dataset.setup.mounts[1])
    guess = truth + np.array([0.3 * np.cos(2.0), 0.3 * np.sin(2.0), np.radians(20.0)])
    start = time.process_time()
    replay(dataset, "lidar_odometry")
    reference = time.process_time() - start
    start = time.process_time()
    estimate = calibrate(dataset, guess=[guess]).mounts[0]
    seconds = time.process_time() - start
    hand_eye = _errors(estimate.hand_eye.mount, truth)
    final = _errors(estimate.value, truth)
    ok = final[0] <= 10.0 and final[1] <= 0.2 and not estimate.unobservable
    std = estimate.std * [1e3, 1e3, 180 / np.pi]
    return (f"| {world} | {trace} | {layout} | {len(dataset)} | {hand_eye[0]:.2f} mm, "
            f"{hand_eye[1]:.3f}° | {final[0]:.2f} mm, {final[1]:.3f}° | {std[0]:.1f}/{std[1]:.1f}"
            f" mm, {std[2]:.3f}° | {seconds:.1f} s ({seconds / reference:.1f}×) | "
            f"{'yes' if ok else 'NO'} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", nargs="+",
                        default=["hallway", "open_cylinders", "closed_to_open", "random"])
    parser.add_argument("--traces", nargs="+", default=["zigzag", "loop"])
    parser.add_argument("--layouts", nargs="+", default=list(LAYOUTS), choices=list(LAYOUTS))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}; CPU time, reference = lidar_odometry over the drive")
    print("| world | trace | layout | scans | hand-eye error | final error | 1-sigma x/y, "
          "heading | CPU (× reference) | within 1 cm, 0.2° |")
    print("|---|---|---|---:|---|---|---|---|---|")
    for world in args.worlds:
        for trace in args.traces:
            for layout in args.layouts:
                print(run_case(world, trace, layout, args.seed), flush=True)


if __name__ == "__main__":
    main()
