"""What a wrong mount costs and what self-calibration buys back, on a simulated drive.

:func:`compare_mounts` runs estimators over one recorded drive three times: with the true
setup, with Lidar 2's mount wrong by a given offset (``x``/``y`` [m] and heading [rad], in
Lidar 2's configured car-frame mount), and with the mounts :func:`calibrate` finds when it
starts from that wrong setup (it sees the scans only, never the truth). Each run is scored
against the true poses (:func:`estimators.evaluation.metrics.evaluate`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from estimators.base import Sensor, SensorSetup
from estimators.calibration.self_calibration import calibrate
from estimators.leaderboard.recording import replay, score
from lidar_env.core import EstimatorInputError

#: Metrics :func:`compare_mounts` reports, in table order.
REPORTED = ("ate_rmse_m", "heading_rmse_deg", "rpe_translation_rmse_m", "accuracy_percent")


def perturbed(setup: SensorSetup, offset: ArrayLike, k: int = 1) -> SensorSetup:
    """``setup`` with Lidar ``k``'s car-frame mount moved by ``offset`` (dx [m], dy [m],
    dheading [rad])."""
    if not 0 < k < setup.n_lidars:
        raise EstimatorInputError(f"k: expected a Lidar index in 1..{setup.n_lidars - 1}, got {k}")
    sensors = list(setup.sensors)
    wrong = sensors[k].mount + np.asarray(offset, dtype=np.float64)
    sensors[k] = Sensor(wrong, sensors[k].beam_angles, sensors[k].max_range)
    return SensorSetup(sensors=sensors, world_aligned=setup.world_aligned)


def compare_mounts(dataset: Any, offset: ArrayLike, estimators: Sequence[str]
                   ) -> dict[str, dict[str, dict[str, float]]]:
    """``{setup name: {estimator: metrics}}`` for the setups ``true``, ``wrong`` and
    ``calibrated`` (see the module docstring); ``dataset`` is a recorded env drive
    (:class:`estimators.leaderboard.records.SensorDataset`)."""
    wrong = perturbed(dataset.setup, offset)
    calibration = calibrate(dataclasses.replace(dataset, setup=wrong))
    setups = {"true": dataset.setup, "wrong": wrong, "calibrated": calibration.setup(wrong)}
    results: dict[str, dict[str, dict[str, float]]] = {}
    for name, setup in setups.items():
        drive = dataclasses.replace(dataset, setup=setup)
        results[name] = {estimator: score(replay(drive, estimator), dataset.poses)
                         for estimator in estimators}
    results["calibrated"]["_mount"] = dict(zip(("x", "y", "heading"),
                                               setups["calibrated"].mounts[1].tolist(),
                                               strict=True))
    return results


def comparison_table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    """A Markdown table of :func:`compare_mounts`' results."""
    lines = ["| setup | estimator | " + " | ".join(REPORTED) + " |",
             "|---|---|" + "---:|" * len(REPORTED)]
    for name, runs in results.items():
        for estimator, metrics in runs.items():
            if not estimator.startswith("_"):
                values = " | ".join(f"{metrics[m]:.4f}" for m in REPORTED)
                lines.append(f"| {name} | {estimator} | {values} |")
    return "\n".join(lines)
