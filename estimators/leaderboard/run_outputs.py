"""The files and the terminal summary of ``duallidar run``.

Per estimator, in ``OUT/<estimator>/`` (names from
:func:`estimators.leaderboard.file_names.safe_file_name`):

* ``estimate.tum``: the trajectory, one pose per scan, in the frame of the first scan;
* ``truth.tum``: the truth poses matched to scans, stamped with their scan's time, so that
  ``evo_ape tum truth.tum estimate.tum -a`` and ``evo_rpe`` read the pair as it is;
* ``relation_errors.csv``: one row per relation (``set``, ``t1``, ``t2`` [s],
  ``translation_m``, ``rotation_deg``);
* ``map.pgm`` + ``map.yaml``: the occupancy map built from every scan at the estimated poses,
  as a ROS ``map_server`` map (:func:`estimators.mapping.ros_map_export.save_grid_as_ros_map`),
  over the extent of the returns;
* ``trajectory.png``: that map with the estimated trajectory and the truth (moved into the
  estimate's frame by the ATE's alignment) on top (needs matplotlib, the ``plots`` extra);
* ``health.json``: what the estimator met in its input (:class:`estimators.health.Health`):
  the counts of skipped scans, frozen scans, clock jumps and blind stretches, and where they
  were, as scan indices from 0 (the rows of ``estimate.tum``): ``skipped``, ``jumps`` and
  ``stretches`` (``[first, last]``).

In ``OUT/``: ``metrics.json`` (the recording, its truth, and one entry per estimator) and
``metrics.csv`` (one row per estimator, the four health counts among its columns). The
terminal table ends in a ``health`` column: ``ok``, or the faults met (``12 skipped,
1 frozen, 2 clock jumps``).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.datasets.real_log import LogRun
from estimators.evaluation.tum import write_tum
from estimators.health import Health
from estimators.leaderboard.file_names import safe_file_name
from estimators.leaderboard.run_sources import RunInput
from estimators.leaderboard.single_run import RunScores
from estimators.mapping.occupancy import OccupancyGrid, bounds_around, sensor_poses
from estimators.mapping.ros_map_export import save_grid_as_ros_map
from estimators.mapping.run_maps import from_estimator_run
from lidar_env.core.se2 import compose, inverse

#: Border [m] around the returns of the written maps.
MAP_MARGIN = 1.0
#: The health counts of a metrics row, each with its words in the terminal table.
HEALTH_WORDS: dict[str, tuple[str, str]] = {
    "skipped_scans": ("skipped", "skipped"), "frozen_scans": ("frozen", "frozen"),
    "clock_jumps": ("clock jump", "clock jumps"),
    "blind_stretches": ("blind stretch", "blind stretches")}
ATE_NOTE = ("ATE: RMSE of the position error over the scans with a truth pose, after the "
            "least-squares rigid SE(2) alignment (rotation + translation, no scale; Umeyama), "
            "as evo_ape -a; relation errors: local = between consecutive truth poses")


def returns_extent(poses: NDArray[np.float64], run_input: RunInput) -> tuple[float, ...]:
    """The rectangle [m] around ``poses`` (N, 3) and every return seen from them, grown by
    :data:`MAP_MARGIN` (beams with no return reach no further than the last wall)."""
    recording = run_input.recording
    setup = recording.setup
    mounts = sensor_poses(poses, setup)
    points = [poses[:, :2]]
    for k, (key, sensor) in enumerate(zip(setup.keys, setup.sensors, strict=True)):
        ranges = recording.scans[key][: len(poses)]
        hit = np.isfinite(ranges) & (ranges < sensor.max_range)
        angles = mounts[:, k, 2:3] + sensor.beam_angles[None, :]
        points.append(np.column_stack([(mounts[:, k, 0:1] + ranges * np.cos(angles))[hit],
                                       (mounts[:, k, 1:2] + ranges * np.sin(angles))[hit]]))
    return bounds_around(np.concatenate(points), MAP_MARGIN)


def build_map(run: LogRun, run_input: RunInput, resolution: float) -> OccupancyGrid:
    """The occupancy grid of every scan at ``run``'s poses, at ``resolution`` [m]."""
    observations = list(run_input.recording.observations())
    return from_estimator_run(run.poses, observations, run_input.recording.setup, resolution,
                              bounds=returns_extent(run.poses, run_input))


def write_estimator_files(out: Path, name: str, run_input: RunInput, run: LogRun,
                          scores: RunScores, resolution: float, figure: bool = True,
                          health: Health | None = None) -> dict[str, Path]:
    """Write the files listed in the module docstring for one estimator; return them by
    kind. ``figure=False`` (or no matplotlib) skips the PNG; ``health=None`` skips
    ``health.json``."""
    directory = out / safe_file_name(name)
    directory.mkdir(parents=True, exist_ok=True)
    written = {"estimate": directory / "estimate.tum"}
    write_tum(written["estimate"], run.times, run.poses)
    if health is not None:
        written["health"] = write_health(directory / "health.json", name, health)
    truth = run_input.truth
    if truth is not None:
        written["truth"] = directory / "truth.tum"
        write_tum(written["truth"], run.times[truth.rows], truth.poses)
    if scores.relations:
        written["relations"] = directory / "relation_errors.csv"
        with written["relations"].open("w", newline="") as handle:
            table = csv.writer(handle)
            table.writerow(["set", "t1", "t2", "translation_m", "rotation_deg"])
            for item in scores.relations:
                for row in zip(item.relations.t1, item.relations.t2,
                               item.errors.translation, item.errors.rotation, strict=True):
                    table.writerow([item.label, *(f"{v:.9g}" for v in row)])
    grid = build_map(run, run_input, resolution)
    maps = save_grid_as_ros_map(grid, directory / "map.yaml")
    written["map"] = next(path for path in maps if path.suffix == ".yaml")
    if figure:
        try:
            written["figure"] = _figure(directory / "trajectory.png", name, run_input, run,
                                        scores, grid)
        except ImportError:
            pass  # the caller says that figures need the plots extra
    return written


def write_health(path: Path, name: str, health: Health) -> Path:
    """``health.json`` at ``path``: ``name``'s fault counts and their scan indices."""
    document = {"estimator": name, "ok": health.ok, **health.counts(),
                "skipped": list(health.skipped), "jumps": list(health.jumps),
                "stretches": [list(stretch) for stretch in health.stretches]}
    path.write_text(json.dumps(document, indent=1, default=_plain) + "\n")
    return path


def health_summary(row: dict[str, Any]) -> str:
    """``ok``, or the faults a metrics row counts (``12 skipped, 1 frozen, 2 clock jumps``);
    ``-`` for a row without health counts."""
    if not all(key in row for key in HEALTH_WORDS):
        return "-"
    parts = [f"{row[key]} {word if row[key] == 1 else plural}"
             for key, (word, plural) in HEALTH_WORDS.items() if row[key]]
    return ", ".join(parts) if parts else "ok"


def _figure(path: Path, name: str, run_input: RunInput, run: LogRun, scores: RunScores,
            grid: OccupancyGrid) -> Path:
    from estimators.mapping.map_figure import save_map_figure

    lines = {f"{name} (estimate)": run.poses}
    title = f"{run_input.name}: {name}"
    if scores.alignment is not None and run_input.truth is not None:
        truth = compose(inverse(scores.alignment.transform), run_input.truth.poses)
        lines[f"truth ({run_input.truth_label}), aligned"] = truth
        title += f"; ATE {scores.ate_rmse_m:.3f} m"
    return save_map_figure(path, {f"map at {name}'s poses": grid}, trajectories=lines,
                           title=title)


def metrics_row(name: str, run_input: RunInput, run: LogRun, scores: RunScores,
                status: str = "ok", health: Health | None = None) -> dict[str, Any]:
    """One estimator's metrics as a flat mapping (units in the keys; ``None`` = not
    measured), ending in ``health``'s four counts when given."""
    row: dict[str, Any] = {
        "estimator": name, "status": status, "scans": len(run.times),
        "truth_poses": None if run_input.truth is None else run_input.truth.matched,
        "ate_rmse_m": scores.ate_rmse_m, "heading_rmse_deg": scores.heading_rmse_deg,
        "drift_percent": scores.drift_percent, "truth_distance_m": scores.distance_m,
    }
    for item in scores.relations:
        summary = item.summary()
        key = safe_file_name(item.label.replace(" ", ""))
        row[f"{key}_relations"] = summary.count
        row[f"{key}_translation_m"] = summary.translation_mean
        row[f"{key}_rotation_deg"] = summary.rotation_mean
    row["ms_per_scan_cpu"] = 1e3 * run.seconds_per_scan
    row["realtime_factor"] = run.realtime_factor
    if health is not None:
        row.update(health.counts())
    return row


def write_metrics(out: Path, run_input: RunInput, rows: Sequence[dict[str, Any]]
                  ) -> tuple[Path, Path]:
    """``OUT/metrics.json`` and ``OUT/metrics.csv``; returns both."""
    truth = run_input.truth
    document = {
        "recording": run_input.recording.source, "scans": len(run_input.recording),
        "lidars": run_input.recording.setup.n_lidars, "truth": run_input.truth_label,
        "truth_matching": None if truth is None else {
            "given": truth.given, "matched": truth.matched, "left_out": truth.left_out,
            "tolerance_s": truth.tolerance},
        "notes": list(run_input.notes), "ate": ATE_NOTE, "estimators": list(rows),
    }
    json_path, csv_path = out / "metrics.json", out / "metrics.csv"
    json_path.write_text(json.dumps(document, indent=1, allow_nan=False,
                                    default=_plain) + "\n")
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with csv_path.open("w", newline="") as handle:
        table = csv.DictWriter(handle, columns)
        table.writeheader()
        table.writerows(rows)
    return json_path, csv_path


def _plain(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else str(value)


def _cell(value: Any, digits: int) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def summary_table(rows: Sequence[dict[str, Any]], windows: Sequence[str]) -> str:
    """The terminal table: ATE beside the local and windowed relation errors, then cost and
    the input's health (:func:`health_summary`)."""
    heads = ["estimator", "ATE [m]", "local [m]", "local [deg]",
             *(f"{w} [m]" for w in windows), "ms/scan", "x real time", "health"]
    body = []
    for row in rows:
        if row["status"] != "ok":
            body.append([row["estimator"], row["status"]])
            continue
        relation_keys = ["local", *(safe_file_name(w.replace(" ", "")) for w in windows)]
        relation_keys = relation_keys if "all_translation_m" not in row else ["local", "all"]
        body.append([row["estimator"], _cell(row["ate_rmse_m"], 5),
                     _cell(row.get("local_translation_m"), 4),
                     _cell(row.get("local_rotation_deg"), 3),
                     *(_cell(row.get(f"{key}_translation_m"), 4) for key in relation_keys[1:]),
                     _cell(row["ms_per_scan_cpu"], 2), _cell(row["realtime_factor"], 1),
                     health_summary(row)])
    if any("all_translation_m" in row for row in rows):
        heads[4:4 + len(windows)] = ["all [m]"]
    full = [heads, *(line for line in body if len(line) == len(heads))]
    widths = [max(len(line[i]) for line in full) for i in range(len(heads))]
    widths[0] = max([widths[0], *(len(line[0]) for line in body)])
    return "\n".join("  ".join(cell.ljust(width) for cell, width in
                               zip(line, widths if len(line) == len(heads) else [widths[0], 0],
                                   strict=True)).rstrip()
                     for line in [heads, *body])
