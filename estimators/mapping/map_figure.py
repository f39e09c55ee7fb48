"""Pictures of occupancy maps: a grid as an RGB overlay (:func:`occupancy_to_rgb`, the adapter
to :func:`lidar_env.rendering.renderer.occupancy_to_rgb`), and figures of maps side by side
(:func:`save_map_figure`: true map, maps at true and estimated poses, trajectories on top;
needs matplotlib, ``pip install 'duallidar[plots]'``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.mapping.occupancy import Bounds, OccupancyGrid
from lidar_env import rendering
from lidar_env.core import EstimatorInputError


def panel_image(
    panel: OccupancyGrid | ArrayLike, bounds: Bounds | None
) -> tuple[NDArray[np.float64], tuple[float, float, float, float]]:
    """A panel as occupancy probabilities and its matplotlib extent (left, right, bottom, top)."""
    if isinstance(panel, OccupancyGrid):
        xmin, ymin, _, _ = panel.bounds
        rows, cols = panel.shape
        extent = (xmin, xmin + cols * panel.resolution, ymin, ymin + rows * panel.resolution)
        return panel.probabilities(), extent
    image = np.asarray(panel)
    if image.ndim != 2:
        raise EstimatorInputError(
            f"map panel: expected an OccupancyGrid or a 2-D image, got {image.shape}")
    if bounds is None:
        raise EstimatorInputError(
            "bounds: expected (xmin, ymin, xmax, ymax) [m] to place an image panel, "
            "got None")
    xmin, ymin, xmax, ymax = bounds
    probability = image / 255.0 if image.dtype == np.uint8 else image.astype(np.float64)
    return probability, (xmin, xmax, ymin, ymax)


def save_map_figure(
    path: str | Path,
    panels: Mapping[str, OccupancyGrid | ArrayLike],
    bounds: Bounds | None = None,
    trajectories: Mapping[str, ArrayLike] | None = None,
    title: str | None = None,
) -> Path:
    """Draw maps side by side and save them as a PNG at ``path``; return the path.

    ``panels`` maps a title to an :class:`OccupancyGrid` (drawn over its own bounds) or an
    image in the grid layout (row 0 = largest y) drawn over ``bounds`` (xmin, ymin, xmax, ymax)
    [m]: uint8 with 255 = obstacle (``world.to_image``) or probabilities in [0, 1]. Dark =
    occupied, white = free, grey = unknown. ``trajectories`` (name -> (N, 3) or (N, 2) [m]) are
    drawn on every panel (legend on the first). Needs matplotlib (the ``plots`` extra).

    Example (the true map next to the maps built at true and at estimated poses)::

        save_map_figure("maps.png", {"true": world.to_image(0.05), "true poses": grid_true,
                                     "pc_fusion": grid_best}, world.bounds,
                        trajectories={"true": truth, "pc_fusion": estimate})
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as error:
        raise ImportError("save_map_figure needs matplotlib: pip install 'duallidar[plots]'") \
            from error
    if not panels:
        raise EstimatorInputError("panels: expected at least one map to draw, got none")
    images = {name: panel_image(panel, bounds) for name, panel in panels.items()}
    aspect = max((e[3] - e[2]) / (e[1] - e[0]) for _, e in images.values())  # height / width
    n_cols = min(len(images), math.ceil(math.sqrt(len(images) / aspect)))  # near square
    n_rows = math.ceil(len(images) / n_cols)
    figure, axes = plt.subplots(n_rows, n_cols, squeeze=False,
                                figsize=(4.5 * n_cols, 4.5 * aspect * n_rows + 0.8))
    for axis in axes.flat[len(images):]:
        axis.set_visible(False)
    drawn = zip(axes.flat[: len(images)], images.items(), strict=True)
    for index, (axis, (name, (image, extent))) in enumerate(drawn):
        axis.imshow(image, cmap="gray_r", vmin=0.0, vmax=1.0, extent=extent, origin="upper",
                    interpolation="nearest")
        for label, trajectory in (trajectories or {}).items():
            points = np.asarray(trajectory, dtype=np.float64)
            axis.plot(points[:, 0], points[:, 1], linewidth=1.0, label=label)
        if trajectories and index == 0:
            axis.legend(loc="upper right", fontsize="small")
        axis.set_xlim(extent[0], extent[1])  # a trajectory that strays keeps the map in view
        axis.set_ylim(extent[2], extent[3])
        axis.set_title(name, fontsize="medium")
        axis.set_xlabel("x [m]")
        axis.set_ylabel("y [m]")
    if title:
        figure.suptitle(title)
    figure.tight_layout()
    path = Path(path)
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return path


def occupancy_to_rgb(
    grid: OccupancyGrid, bounds: Bounds | None = None, resolution: float | None = None
) -> NDArray[np.uint8]:
    """An ``(H, W, 3)`` uint8 picture of ``grid`` for overlays, row 0 = largest ``y``
    (:func:`lidar_env.rendering.renderer.occupancy_to_rgb` of its probabilities).

    Grey level ``255 * (1 - p)``: occupied cells dark, free cells white, unobserved cells
    mid-grey (128). The picture spans ``bounds`` (default: the grid's) at ``resolution``
    [m/pixel] (default: the grid's), sampled at pixel centres (nearest cell); area outside the
    grid is unobserved."""
    bounds = grid.bounds if bounds is None else bounds
    resolution = grid.resolution if resolution is None else resolution
    OccupancyGrid(bounds, resolution)  # validates the picture's bounds and pixel size
    return rendering.occupancy_to_rgb(
        grid.probabilities(), grid.bounds, grid.resolution, bounds, resolution
    )
