"""The leaderboard's figures (matplotlib, ``pip install 'duallidar[plots]'``): Fig. 8, the eq.-5
Lidar image and every estimator's trace per group (:func:`draw_figure_8`), and the occupancy
maps of the true poses, the best estimator and the paper's (:func:`draw_map_figure`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.matrix import (
    Group,
)
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.tables import (
    PAPER_ESTIMATOR,
    _fmt,
)
from estimators.leaderboard.tasks import EstimatorSpec


def draw_figure_8(db: ExperimentDatabase, groups: Sequence[Group],
                  scenarios: dict[str, list[Scenario]],
                  records: dict[tuple[Scenario, str], TraceRecord],
                  specs: Sequence[EstimatorSpec], out: Path) -> list[Path]:
    """Fig. 8: an eq.-5 Lidar image, and per group (first seed) the true trace and every
    estimator's trace over the world map. Returns the PNG paths."""
    from matplotlib.figure import Figure

    from estimators.leaderboard.recording import world_from_geometry
    from estimators.paper.scan_image import scan_to_image

    first = [(group, scenarios[group.name][0]) for group in groups if scenarios[group.name]]
    first = [(g, s) for g, s in first if db.has_sensor_dataset(s)]
    if not first:
        return []
    paths = []
    dataset = db.load_sensor_dataset(first[0][1])
    step = len(dataset) // 2
    image = scan_to_image(dataset.scans["lidar_1"][step], dataset.setup.beam_angles,
                          dataset.setup.max_range)
    figure = Figure(figsize=(6, 5))
    axes = figure.add_subplot()
    shown = axes.imshow(image, cmap="gray_r", interpolation="none")
    figure.colorbar(shown, ax=axes, label="pixel value (eq. 5)")
    axes.set_title(f"eq. 5 Lidar image: {first[0][1].label}, step {step}, lidar_1", fontsize=9)
    axes.set_xlabel("column [px]")
    axes.set_ylabel("row [px]")
    paths.append(out / "fig8_lidar_image.png")
    figure.savefig(paths[-1], dpi=150, bbox_inches="tight")

    columns = min(2, len(first))
    rows = -(-len(first) // columns)
    figure = Figure(figsize=(7 * columns, 5 * rows), layout="constrained")
    colours = [f"C{i % 10}" for i in range(len(specs))]
    for index, (group, scenario) in enumerate(first, 1):
        axes = figure.add_subplot(rows, columns, index)
        dataset = db.load_sensor_dataset(scenario)
        world = world_from_geometry(dataset.world)  # the map as it was recorded
        xmin, ymin, xmax, ymax = world.bounds
        axes.imshow(world.to_image(0.05), cmap="gray_r", extent=(xmin, xmax, ymin, ymax),
                    vmax=400)
        truth = dataset.poses
        axes.plot(truth[:, 0], truth[:, 1], "k-", linewidth=3, label="truth")
        with_poses = {r.trace_id: r for r in db.traces(scenario)}
        for spec, colour in zip(specs, colours, strict=True):
            key = (scenario, spec.name)
            record = with_poses[records[key].trace_id] if key in records else None
            if record is not None:
                poses = record.trace.poses
                axes.plot(poses[:, 0], poses[:, 1], "-", color=colour, linewidth=1.2,
                          label=spec.name)
        axes.set_xlim(xmin, xmax)
        axes.set_ylim(ymin, ymax)
        axes.set_aspect("equal")
        axes.set_title(f"{group.name} (seed {scenario.seed})")
        axes.set_xlabel("x [m]")
        axes.set_ylabel("y [m]")
    figure.legend(*axes.get_legend_handles_labels(), loc="outside right upper",
                  fontsize="small")
    paths.append(out / "fig8_traces.png")
    figure.savefig(paths[-1], dpi=80, bbox_inches="tight")
    return paths


def draw_map_figure(db: ExperimentDatabase, groups: Sequence[Group],
                    scenarios: dict[str, list[Scenario]],
                    records: dict[tuple[Scenario, str], TraceRecord],
                    ranked: Sequence[str], out: Path) -> list[Path]:
    """``maps.png``: the true map of the first group whose world has cylinders (else the first
    group), first seed, next to the occupancy maps built from its scans at the poses of the
    best-ranked estimator (first of ``ranked`` that ran there) and of :data:`PAPER_ESTIMATOR`,
    as scored (:data:`estimators.leaderboard.recording.MAP_RESOLUTION`). Returns the PNG paths."""
    from estimators.leaderboard.recording import MAP_RESOLUTION, world_from_geometry
    from estimators.mapping.map_figure import save_map_figure
    from estimators.mapping.occupancy import from_estimator_run

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
    panels: dict[str, Any] = {"true map": world.to_image(MAP_RESOLUTION)}
    trajectories = {"truth": dataset.poses}
    for name in shown:
        record = records[(scenario, name)]
        poses = by_id[record.trace_id].trace.poses
        role = "paper" if name == PAPER_ESTIMATOR else "best"
        iou = record.metrics.get("map_iou", math.nan)
        panels[f"{role}: {name} (IoU {_fmt(iou)})"] = from_estimator_run(
            poses, observations, dataset.setup, MAP_RESOLUTION, bounds=world.bounds)
        trajectories[name] = poses
    path = save_map_figure(out / "maps.png", panels, world.bounds, trajectories,
                           title=f"{group.name}, seed {scenario.seed}: occupancy maps, "
                                 f"{100 * MAP_RESOLUTION:.0f} cm cells")
    return [path]
