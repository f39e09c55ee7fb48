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
#: Height over width of the lead figure's trace panel.
LEAD_PANEL_ASPECT = 0.5
#: Widest figure [in]: the report shows figures at 96 px per inch, and 13 in fit its column.
MAX_FIGURE_WIDTH = 13.0


def _first_runs(db: ExperimentDatabase, groups: Sequence[Group],
                scenarios: dict[str, list[Scenario]]) -> list[tuple[Group, Scenario]]:
    """Per group its first seed's scenario, where the sensor dataset is stored."""
    first = [(group, scenarios[group.name][0]) for group in groups if scenarios[group.name]]
    return [(g, s) for g, s in first if db.has_sensor_dataset(s)]


def scan_extent(image: Any, resolution: float, margin: float = 0.5
                ) -> tuple[float, float, float, float]:
    """The box ``(xmin, xmax, ymin, ymax)`` [m, sensor frame] around the non-zero pixels of an
    eq.-5 image (geometry of :mod:`estimators.paper.scan_image`: the sensor at the centre, x
    along the columns, y up the rows) and the sensor itself, grown by ``margin`` [m]; the
    whole image when no pixel is set."""
    size = image.shape[0]
    rows, columns = np.nonzero(image)
    half = resolution * size / 2.0
    if len(rows) == 0:
        return -half, half, -half, half
    xs = (columns - size / 2) * resolution  # left edges of the pixels
    ys = (size / 2 - 1 - rows) * resolution  # bottom edges
    xmin, xmax = min(0.0, float(xs.min())), max(0.0, float(xs.max()) + resolution)
    ymin, ymax = min(0.0, float(ys.min())), max(0.0, float(ys.max()) + resolution)
    return (max(-half, xmin - margin), min(half, xmax + margin),
            max(-half, ymin - margin), min(half, ymax + margin))


def draw_lidar_image(db: ExperimentDatabase, scenario: Scenario, out: Path) -> list[Path]:
    """``fig8_lidar_image.png`` (+ ``.svg``): the eq.-5 image of ``lidar_1``'s scan half way
    through ``scenario``, on metric axes in the sensor frame [m], cropped to the scan's extent
    and the sensor (:func:`scan_extent`; the image itself spans ±max_range), each pixel drawn
    3 pixels wide (a grey dilation) so that single returns stay visible at print size."""
    from matplotlib.figure import Figure

    from estimators.paper.scan_image import DEFAULT_SIZE, scan_to_image

    dataset = db.load_sensor_dataset(scenario)
    step = len(dataset) // 2
    image = scan_to_image(dataset.scans["lidar_1"][step], dataset.setup.beam_angles,
                          dataset.setup.max_range)
    from scipy.ndimage import grey_dilation

    half = dataset.setup.max_range  # the default image spans +-max_range in DEFAULT_SIZE px
    xmin, xmax, ymin, ymax = scan_extent(image, 2 * half / DEFAULT_SIZE)
    width = 5.0
    height = min(6.0, max(2.6, (width - 1.2) * (ymax - ymin) / (xmax - xmin) + 1.0))
    figure = Figure(figsize=(width, height), layout="constrained")
    axes = figure.add_subplot()
    # one image pixel is about one screen pixel at print size: drawn 3 px wide, it shows
    shown = axes.imshow(grey_dilation(image, size=(3, 3)), cmap="gray_r", interpolation="none",
                        extent=(-half, half, -half, half))
    axes.plot([0.0], [0.0], marker="+", color="#d62728", markersize=10, linestyle="none")
    axes.set(xlim=(xmin, xmax), ylim=(ymin, ymax), aspect="equal")
    figure.colorbar(shown, ax=axes, label="pixel value (eq. 5)", shrink=0.9)
    axes.set_title(f"eq.-5 image of lidar_1, {scenario.label}, step {step}\n"
                   f"{DEFAULT_SIZE} px square, {2 * half / DEFAULT_SIZE:.3f} m/px, each pixel "
                   "drawn 3 px wide; + = sensor", fontsize=8)
    axes.set_xlabel("x, sensor forward [m]")
    axes.set_ylabel("y, sensor left [m]")
    return save_figure(figure, out / "fig8_lidar_image.png")


def _draw_position_error(axes: Any, poses: Any, truth: Any, name: str) -> None:
    """The position error of ``poses`` against ``truth`` over the distance travelled, in
    estimator ``name``'s style, on a log axis floored at :data:`ERROR_FLOOR`."""
    distance, error = error_along_distance(poses, truth)
    style = estimator_style(name)
    axes.plot(distance, np.maximum(error, ERROR_FLOOR), color=style.colour,
              linewidth=ESTIMATE_WIDTH, marker=style.marker,
              markevery=max(1, len(distance) // 8), markersize=5, label=name)


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
            _draw_position_error(errors, poses, truth, spec.name)
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


def drive_extent(truth: Any, estimates: Sequence[Any], bounds: Sequence[float]
                 ) -> tuple[float, float, float, float]:
    """The box ``(xmin, ymin, xmax, ymax)`` [m] around the true and estimated positions (each
    ``(N, 3)`` poses), cut to the world's ``bounds`` and grown by a tenth of its size (at least
    1 m): where the drive happened, not the whole world."""
    points = np.concatenate([np.asarray(truth)[:, :2],
                             *(np.asarray(p)[:, :2] for p in estimates)])
    points = points[np.all(np.isfinite(points), axis=1)]
    low = np.maximum(points.min(axis=0), bounds[:2])
    high = np.minimum(points.max(axis=0), bounds[2:])
    margin = max(1.0, 0.1 * float(np.max(high - low)))
    return (float(low[0] - margin), float(low[1] - margin), float(high[0] + margin),
            float(high[1] + margin))


def with_aspect(box: tuple[float, float, float, float], aspect: float
                ) -> tuple[float, float, float, float]:
    """``box`` (xmin, ymin, xmax, ymax) grown about its centre along one axis until its height
    over width is ``aspect`` (so a panel of that shape shows it at equal scale, filled)."""
    xmin, ymin, xmax, ymax = box
    width, height = xmax - xmin, ymax - ymin
    if height < aspect * width:
        grow = (aspect * width - height) / 2
        return xmin, ymin - grow, xmax, ymax + grow
    grow = (height / aspect - width) / 2
    return xmin - grow, ymin, xmax + grow, ymax


def draw_lead_figure(db: ExperimentDatabase, groups: Sequence[Group],
                     scenarios: dict[str, list[Scenario]],
                     records: dict[tuple[Scenario, str], TraceRecord],
                     ranked: Sequence[str], out: Path) -> list[Path]:
    """``lead_traces.png`` (+ ``.svg``), the report's first figure, sized to sit beside the
    headline table: the first group's first-seed run, its true trace (black) and every
    estimator's over the world, zoomed on the drive (:func:`drive_extent`), above each one's
    position error over the distance travelled; the legend in ``ranked`` order (best first)."""
    from matplotlib.figure import Figure

    from estimators.leaderboard.recording import world_from_geometry

    first = _first_runs(db, groups, scenarios)
    if not first:
        return []
    group, scenario = first[0]
    dataset = db.load_sensor_dataset(scenario)
    stored = {r.trace_id: r for r in db.traces(scenario)}
    estimates = {name: stored[records[(scenario, name)].trace_id].trace.poses
                 for name in ranked if (scenario, name) in records}
    figure = Figure(figsize=(5.6, 5.0), layout="constrained")
    traces, errors = figure.subplots(2, 1, height_ratios=(1.2, 1))
    bounds = draw_obstacles(traces, world_from_geometry(dataset.world))
    for name, poses in estimates.items():
        draw_clipped_trace(traces, poses, bounds, name)
        _draw_position_error(errors, poses, dataset.poses, name)
    draw_clipped_trace(traces, dataset.poses, bounds, None)
    xmin, ymin, xmax, ymax = with_aspect(
        drive_extent(dataset.poses, list(estimates.values()), bounds), LEAD_PANEL_ASPECT)
    traces.set(xlim=(xmin, xmax), ylim=(ymin, ymax), xlabel="x [m]", ylabel="y [m]",
               aspect="equal")
    traces.set_title(f"{group.name}, seed {scenario.seed}: traces (truth black)",
                     fontsize="medium")
    errors.set(yscale="log", xlabel="distance travelled [m]", ylabel="position error [m]")
    errors.grid(True, which="both", alpha=0.3)
    handles, labels = traces.get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", fontsize="small",
                  ncol=min(4, len(labels)))
    return save_figure(figure, out / "lead_traces.png")


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
    """Occupancy images, two to a row (one when the map is over twice as wide as tall)
    (``panels``: title -> (probabilities in [0, 1], row 0 = largest y; matplotlib extent
    (left, right, bottom, top) [m])), shown over ``bounds`` (xmin, ymin, xmax, ymax) [m], with
    a colour bar, every trajectory (``"truth"`` black on top, others in their estimator style,
    clipped to the map) on every panel and the legend in the margin. Returns the PNG and SVG
    written."""
    from matplotlib.figure import Figure

    xmin, ymin, xmax, ymax = bounds
    aspect = (ymax - ymin) / (xmax - xmin)
    columns = 1 if aspect < 0.5 else min(2, len(panels))  # wide maps: one above the other
    rows = math.ceil(len(panels) / columns)
    # at most MAX_FIGURE_WIDTH wide, so that the report shows it at print size, unscaled
    side = min(9.0 if columns == 1 else 6.5, (MAX_FIGURE_WIDTH - 1.8) / columns)
    figure = Figure(figsize=(side * columns + 1.8, side * aspect * rows + 2.0),
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
