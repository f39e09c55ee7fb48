"""The leaderboard's figures (matplotlib, ``pip install 'duallidar[plots]'``): Fig. 8, the eq.-5
Lidar image and every estimator's trace per group (:func:`draw_figure_8`), and the occupancy
maps of the true poses, the best estimator and the paper's (:func:`draw_map_figure`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.matrix import Group
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.style import (
    ESTIMATE_WIDTH,
    estimator_style,
    figure_title,
    save_figure,
)
from estimators.leaderboard.tables import PAPER_ESTIMATOR, format_number
from estimators.leaderboard.tasks import EstimatorSpec
from estimators.leaderboard.trace_drawing import (
    draw_clipped_trace,
    draw_obstacles,
    error_along_distance,
    legend_outside,
)

#: Smallest position error drawn on the log axis [m] (a trace that starts exact is at 0).
ERROR_FLOOR = 1e-4


def _first_runs(db: ExperimentDatabase, groups: Sequence[Group],
                scenarios: dict[str, list[Scenario]]) -> list[tuple[Group, Scenario]]:
    """Per group its first seed's scenario, where the sensor dataset is stored."""
    first = [(group, scenarios[group.name][0]) for group in groups if scenarios[group.name]]
    return [(g, s) for g, s in first if db.has_sensor_dataset(s)]


def draw_lidar_image(db: ExperimentDatabase, scenario: Scenario, out: Path) -> list[Path]:
    """``fig8_lidar_image.png`` (+ ``.svg``): the eq.-5 image of ``lidar_1``'s scan half way
    through ``scenario``, on metric axes in the sensor frame [m]."""
    from matplotlib.figure import Figure

    from estimators.paper.scan_image import DEFAULT_SIZE, scan_to_image

    dataset = db.load_sensor_dataset(scenario)
    step = len(dataset) // 2
    image = scan_to_image(dataset.scans["lidar_1"][step], dataset.setup.beam_angles,
                          dataset.setup.max_range)
    half = dataset.setup.max_range  # the default image spans +-max_range in DEFAULT_SIZE px
    figure = Figure(figsize=(6, 5), layout="constrained")
    axes = figure.add_subplot()
    shown = axes.imshow(image, cmap="gray_r", interpolation="none",
                        extent=(-half, half, -half, half))
    figure.colorbar(shown, ax=axes, label="pixel value (eq. 5), 0 = no return")
    axes.set_title(f"eq.-5 Lidar image of lidar_1, {scenario.label}, step {step}\n"
                   f"({DEFAULT_SIZE} x {DEFAULT_SIZE} px, {2 * half / DEFAULT_SIZE:.3f} m/px)",
                   fontsize=9)
    axes.set_xlabel("x, sensor forward [m]")
    axes.set_ylabel("y, sensor left [m]")
    return save_figure(figure, out / "fig8_lidar_image.png")


def draw_figure_8(db: ExperimentDatabase, groups: Sequence[Group],
                  scenarios: dict[str, list[Scenario]],
                  records: dict[tuple[Scenario, str], TraceRecord],
                  specs: Sequence[EstimatorSpec], out: Path) -> list[Path]:
    """Fig. 8: the eq.-5 Lidar image (:func:`draw_lidar_image`) and ``fig8_traces.png``: per
    group (first seed) the true trace (black, on top) and every estimator's trace over the
    world's obstacles, clipped to the world with an arrow where a trace leaves it, beside the
    position error of each estimator over the distance travelled (where the good ones overlap
    the truth, the error panel tells them apart). Returns the files written (PNG and SVG)."""
    from matplotlib.figure import Figure

    from estimators.leaderboard.recording import world_from_geometry

    first = _first_runs(db, groups, scenarios)
    if not first:
        return []
    paths = draw_lidar_image(db, first[0][1], out)
    figure = Figure(figsize=(13, 4.4 * len(first)), layout="constrained")
    grid = figure.subplots(len(first), 2, squeeze=False, width_ratios=(1.15, 1))
    for (group, scenario), (traces, errors) in zip(first, grid, strict=True):
        dataset = db.load_sensor_dataset(scenario)
        bounds = draw_obstacles(traces, world_from_geometry(dataset.world))
        truth = dataset.poses
        with_poses = {r.trace_id: r for r in db.traces(scenario)}
        for spec in specs:
            if (scenario, spec.name) not in records:
                continue
            poses = with_poses[records[(scenario, spec.name)].trace_id].trace.poses
            draw_clipped_trace(traces, poses, bounds, spec.name)
            distance, error = error_along_distance(poses, truth)
            style = estimator_style(spec.name)
            errors.plot(distance, np.maximum(error, ERROR_FLOOR), color=style.colour,
                        linewidth=ESTIMATE_WIDTH, marker=style.marker,
                        markevery=max(1, len(distance) // 8), markersize=5, label=spec.name)
        draw_clipped_trace(traces, truth, bounds, None)
        traces.set(xlim=(bounds[0], bounds[2]), ylim=(bounds[1], bounds[3]), aspect="equal",
                   xlabel="x [m]", ylabel="y [m]",
                   title=f"{group.name}, seed {scenario.seed}: estimated traces over the map")
        errors.set(yscale="log", xlabel="distance travelled along the truth [m]",
                   ylabel="position error [m] (log)",
                   title=f"{group.name}, seed {scenario.seed}: position error")
        errors.grid(True, which="both", alpha=0.3)
    figure_title(figure, "Fig. 8: every estimator's trace against the truth (black), one run per "
                    "group; arrows mark where a trace leaves the world")
    legend_outside(figure, grid[0][0])
    return paths + save_figure(figure, out / "fig8_traces.png")


def draw_map_figure(db: ExperimentDatabase, groups: Sequence[Group],
                    scenarios: dict[str, list[Scenario]],
                    records: dict[tuple[Scenario, str], TraceRecord],
                    ranked: Sequence[str], out: Path) -> list[Path]:
    """``maps.png``: the true map of the first group whose world has cylinders (else the first
    group), first seed, next to the occupancy maps built from its scans at the poses of the
    best-ranked estimator (first of ``ranked`` that ran there) and of :data:`PAPER_ESTIMATOR`,
    as scored (:data:`estimators.leaderboard.recording.MAP_RESOLUTION`). Returns the PNG paths."""
    from estimators.leaderboard.recording import MAP_RESOLUTION, world_from_geometry
    from estimators.mapping.map_figure import panel_image
    from estimators.mapping.run_maps import from_estimator_run

    candidates = [(g, scenarios[g.name][0]) for g in groups if scenarios[g.name]]
    candidates = [(g, s) for g, s in candidates if db.has_sensor_dataset(s)]
    if not candidates:
        return []

    def has_cylinders(scenario: Scenario) -> bool:
        world = db.load_sensor_dataset(scenario).world
        return bool(world) and len(world["circles"]) > 0

    group, scenario = next((c for c in candidates if has_cylinders(c[1])), candidates[0])
    dataset = db.load_sensor_dataset(scenario)
    if not dataset.world:
        return []
    ran = [name for name in ranked if (scenario, name) in records]
    shown = list(dict.fromkeys(ran[:1] + [n for n in ran if n == PAPER_ESTIMATOR]))
    if not shown:
        return []
    world = world_from_geometry(dataset.world)
    observations = list(dataset.observations())
    by_id = {r.trace_id: r for r in db.traces(scenario)}
    panels = {"true map": panel_image(world.to_image(MAP_RESOLUTION), world.bounds)}
    trajectories = {"truth": dataset.poses}
    for name in shown:
        record = records[(scenario, name)]
        poses = by_id[record.trace_id].trace.poses
        role = "paper" if name == PAPER_ESTIMATOR else "best"
        iou = record.metrics.get("map_iou", math.nan)
        grid = from_estimator_run(poses, observations, dataset.setup, MAP_RESOLUTION,
                                  bounds=world.bounds)
        panels[f"map at {role} poses: {name} (IoU {format_number(iou)})"] = panel_image(grid, None)
        trajectories[name] = poses
    title = (f"Occupancy maps, {group.name}, seed {scenario.seed}, {100 * MAP_RESOLUTION:.0f} "
             "cm cells: the true map and the maps built from the scans at estimated poses")
    return draw_occupancy_panels(panels, world.bounds, trajectories, title, out / "maps.png")


def draw_occupancy_panels(panels: dict[str, tuple[Any, tuple[float, float, float, float]]],
                          bounds: Sequence[float], trajectories: dict[str, Any], title: str,
                          path: Path) -> list[Path]:
    """Occupancy images side by side (``panels``: title -> (probabilities in [0, 1], row 0 =
    largest y; matplotlib extent (left, right, bottom, top) [m])), shown over ``bounds``
    (xmin, ymin, xmax, ymax) [m], with a colour bar, every
    trajectory (``"truth"`` black on top, others in their estimator style, clipped to the map)
    on every panel and the legend in the margin. Returns the PNG and SVG written."""
    from matplotlib.figure import Figure

    xmin, ymin, xmax, ymax = bounds
    aspect = (ymax - ymin) / (xmax - xmin)
    columns = 1 if aspect < 0.5 else min(3, len(panels))  # wide maps: one above the other
    rows = math.ceil(len(panels) / columns)
    figure = Figure(figsize=(6.5 * columns + 1.8, 6.5 * aspect * rows + 2.0),
                    layout="constrained")
    axes = figure.subplots(rows, columns, squeeze=False).flatten()
    for axis in axes[len(panels):]:
        axis.set_visible(False)
    axes = axes[:len(panels)]
    for axis, (name, (image, extent)) in zip(axes, panels.items(), strict=True):
        shown = axis.imshow(image, cmap="gray_r", vmin=0.0, vmax=1.0, origin="upper",
                            extent=extent, interpolation="nearest")
        for label, poses in trajectories.items():
            if label != "truth":
                draw_clipped_trace(axis, np.asarray(poses), bounds, label)
        if "truth" in trajectories:
            draw_clipped_trace(axis, np.asarray(trajectories["truth"]), bounds, None)
        axis.set(xlim=(xmin, xmax), ylim=(ymin, ymax), aspect="equal", xlabel="x [m]",
                 ylabel="y [m]", title=name)
        axis.title.set_fontsize("medium")
    figure.colorbar(shown, ax=list(axes), location="bottom", shrink=0.6, aspect=40,
                    label="occupancy probability (0 free, 0.5 unobserved, 1 occupied)")
    figure_title(figure, title)
    legend_outside(figure, axes[0])
    return save_figure(figure, path)
