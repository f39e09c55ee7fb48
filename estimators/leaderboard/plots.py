"""The leaderboard's summary plots (matplotlib, the ``plots`` extra): the KITTI-style relative
error over segments of growing length per estimator (:func:`draw_segment_errors`, with the
arithmetic in :func:`segment_errors`), the distribution of each estimator's relation errors on
a real log (:func:`draw_relation_histograms`) and the cost/accuracy trade-off, one point per
estimator (:func:`draw_speed_accuracy`). Every figure is written as a PNG and an SVG.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.evaluation.relations import Relations
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.style import (
    ESTIMATE_WIDTH,
    estimator_style,
    figure_title,
    save_figure,
)
from estimators.leaderboard.trace_drawing import legend_outside
from lidar_env.core.se2 import relative

#: Segment lengths [m] of the relative-error plot (KITTI uses 100-800 m on car drives; these
#: are scaled to indoor traces of tens of metres).
SEGMENT_LENGTHS = (1.0, 2.0, 5.0, 10.0, 20.0)
#: Start a segment every this many steps (KITTI: every 10th frame).
SEGMENT_STRIDE = 10
#: Smallest mean drawn on the log axes (an estimator that never turns has exactly 0 there).
PLOT_FLOOR = 1e-4


def segment_errors(estimate: NDArray[np.float64], truth: NDArray[np.float64],
                   lengths: Sequence[float] = SEGMENT_LENGTHS, stride: int = SEGMENT_STRIDE
                   ) -> dict[float, tuple[list[float], list[float]]]:
    """KITTI's odometry error of ``estimate`` against ``truth`` (both ``(N, 3)`` poses of the
    same steps): for each length L [m] and each ``stride``-th start step, the segment to the
    first step at least L further along the truth; its relative-motion error as translation
    [% of L] and rotation [deg/m]. Returns ``{L: (translation %, rotation deg/m)}`` for the
    lengths the trace is long enough for."""
    steps = np.hypot(*np.diff(truth[:, :2], axis=0).T)
    distance = np.concatenate([[0.0], np.cumsum(steps)])
    errors: dict[float, tuple[list[float], list[float]]] = {}
    for length in lengths:
        starts = np.arange(0, len(truth), stride)
        ends = np.searchsorted(distance, distance[starts] + length)
        keep = ends < len(truth)
        if not np.any(keep):
            continue
        first, last = starts[keep], ends[keep]
        error = relative(relative(truth[first], truth[last]),
                         relative(estimate[first], estimate[last]))
        errors[length] = (list(100.0 * np.hypot(error[:, 0], error[:, 1]) / length),
                          list(np.degrees(np.abs(error[:, 2])) / length))
    return errors


def draw_segment_errors(db: ExperimentDatabase, runs: Sequence[Scenario], names: Sequence[str],
                        records: Mapping[tuple[Scenario, str], TraceRecord],
                        out: Path) -> list[Path]:
    """``segment_errors.png``: per estimator the mean relative translation [%] and rotation
    [deg/m] error over every segment of every simulated run in ``runs``, against the segment
    length (like the KITTI odometry plots)."""
    from matplotlib.figure import Figure

    pooled: dict[str, dict[float, tuple[list[float], list[float]]]] = {n: {} for n in names}
    for scenario in runs:
        if not db.has_sensor_dataset(scenario):
            continue
        truth = db.load_sensor_dataset(scenario).poses
        stored = {r.trace_id: r for r in db.traces(scenario)}
        for name in names:
            if (scenario, name) in records:
                poses = stored[records[(scenario, name)].trace_id].trace.poses
                for length, (moved, turned) in segment_errors(poses, truth).items():
                    into = pooled[name].setdefault(length, ([], []))
                    into[0].extend(moved)
                    into[1].extend(turned)
    if not any(pooled.values()):
        return []
    figure = Figure(figsize=(11, 4.2), layout="constrained")
    moved_axes, turned_axes = figure.subplots(1, 2)
    for name, by_length in pooled.items():
        if by_length:
            lengths = sorted(by_length)
            style = estimator_style(name)
            for axes, part in ((moved_axes, 0), (turned_axes, 1)):
                means = [max(float(np.mean(by_length[x][part])), PLOT_FLOOR) for x in lengths]
                axes.plot(lengths, means, "-",
                          marker=style.marker, color=style.colour, linewidth=ESTIMATE_WIDTH,
                          label=name)
    moved_axes.set(xlabel="segment length [m]", ylabel="translation error [% of length]",
                   yscale="log", title="relative translation error")
    turned_axes.set(xlabel="segment length [m]", ylabel="rotation error [deg/m]",
                    yscale="log", title="relative rotation error")
    for axes in (moved_axes, turned_axes):
        axes.grid(True, which="both", alpha=0.3)
    figure_title(figure, "Error over distance travelled (KITTI-style): mean over segments "
                 f"starting every {SEGMENT_STRIDE} steps of {len(runs)} simulated runs")
    legend_outside(figure, moved_axes)
    return save_figure(figure, out / "segment_errors.png")


def relation_error_samples(db: ExperimentDatabase, scenario: Scenario, relations: Relations,
                           names: Sequence[str],
                           records: Mapping[tuple[Scenario, str], TraceRecord]
                           ) -> dict[str, NDArray[np.float64]]:
    """Per estimator that ran on the real-log ``scenario``, the translation error [m] of each
    ground-truth relation of ``relations`` inside its trace's time span (as scored)."""
    from estimators.evaluation.relations import relation_errors

    stored = {r.trace_id: r for r in db.traces(scenario)}
    samples = {}
    for name in names:
        if (scenario, name) not in records:
            continue
        trace = stored[records[(scenario, name)].trace_id].trace
        ends = np.stack([relations.t1, relations.t2])
        inside = np.all((ends >= trace.times[0] - 1e-3) & (ends <= trace.times[-1] + 1e-3),
                        axis=0)
        samples[name] = relation_errors(trace.times, trace.poses,
                                        relations.select(inside)).translation
    return samples


def draw_relation_histograms(errors: Mapping[str, NDArray[np.float64]], log_name: str,
                             out: Path) -> list[Path]:
    """``relation_errors.png``: one histogram per estimator of its relation translation errors
    [m] on a real log (``errors``: estimator -> per-relation errors), on shared log bins."""
    from matplotlib.figure import Figure

    errors = {name: np.asarray(e) for name, e in errors.items() if len(e)}
    if not errors:
        return []
    every = np.concatenate(list(errors.values()))
    low = max(float(np.min(every[every > 0], initial=1e-4)), 1e-4)
    bins = np.geomspace(low, max(float(np.max(every)), 10 * low), 30)
    columns = min(3, len(errors))
    rows = math.ceil(len(errors) / columns)
    figure = Figure(figsize=(4 * columns, 2.6 * rows + 0.6), layout="constrained")
    grid = figure.subplots(rows, columns, squeeze=False, sharex=True)
    for axes in grid.flat[len(errors):]:
        axes.set_visible(False)
    for axes, (name, values) in zip(grid.flat, errors.items(), strict=False):
        style = estimator_style(name)
        axes.hist(np.clip(values, bins[0], bins[-1]), bins=bins, color=style.colour)
        axes.axvline(float(np.mean(values)), color="black", linestyle="--", linewidth=1)
        axes.set(xscale="log", title=f"{name}: mean {np.mean(values):.3f} m (n={len(values)})",
                 xlabel="relation translation error [m]", ylabel="relations")
        axes.title.set_fontsize("medium")
    figure_title(figure, f"{log_name}: translation error of each ground-truth relation "
                    "(Kümmerle et al. 2009); dashed = mean")
    return save_figure(figure, out / "relation_errors.png")


def draw_speed_accuracy(rows: Sequence[Mapping[str, Any]], out: Path) -> list[Path]:
    """``speed_accuracy.png``: each estimator's ms/step against its ATE (left) and eq.-11
    accuracy (right), error bars = std over seeds (rows of
    :func:`estimators.leaderboard.headline.annotate_rows`)."""
    from matplotlib.figure import Figure

    shown = [r for r in rows if math.isfinite(r.get("ms_per_step", math.nan))
             and math.isfinite(r.get("ate_rmse_m", math.nan))]
    if not shown:
        return []
    figure = Figure(figsize=(11, 4.2), layout="constrained")
    ate_axes, accuracy_axes = figure.subplots(1, 2, sharex=True)
    for row in shown:
        style = estimator_style(row["estimator"])
        for axes, key in ((ate_axes, "ate_rmse_m"), (accuracy_axes, "accuracy_percent")):
            axes.errorbar(row["ms_per_step"], row[key], yerr=row.get(f"{key}_std", 0.0),
                          xerr=row.get("ms_per_step_std", 0.0), marker=style.marker,
                          color=style.colour, markersize=8, linestyle="none", capsize=3,
                          label=row["estimator"])
    ate_axes.set(xscale="log", yscale="log", xlabel="update time [ms/step]",
                 ylabel="ATE RMSE [m] (lower is better)", title="cost vs trajectory error")
    accuracy_axes.set(xscale="log", xlabel="update time [ms/step]",
                      ylabel="eq.-11 accuracy [%] (higher is better)",
                      title="cost vs eq.-11 accuracy")
    for axes in (ate_axes, accuracy_axes):
        axes.grid(True, which="both", alpha=0.3)
    figure_title(figure, "Cost against accuracy: one point per estimator, mean ± std over seeds")
    legend_outside(figure, ate_axes)
    return save_figure(figure, out / "speed_accuracy.png")
