"""The leaderboard: every registered estimator on the paper's scenarios, Table I and Fig. 8.

``duallidar-leaderboard`` (or ``python -m estimators.leaderboard``) records each scenario of
the matrix once into the experiment database (:mod:`estimators.leaderboard.database`), replays
it through every estimator (:mod:`estimators.leaderboard.runner`), scores it
(:mod:`estimators.evaluation.metrics`) and writes

* ``leaderboard.md`` / ``leaderboard.csv``: estimators ranked by mean ATE over all simulated
  scenarios (eq. 11 ignores direction, so it cannot rank alone), with eq.-11 accuracy, heading
  RMSE, drift, ms/step, the scores of the map the estimator's poses yield (occupied-cell IoU,
  precision and recall at 10 cm cells and one cell of tolerance; cylinder recall and centre
  error where the world has cylinders; :func:`estimators.leaderboard.recording.score_map`), one
  column per scenario group and the real-log relation error;
* ``results.csv``: one row per estimator and scenario;
* ``table1.md`` / ``table1.csv``: the paper's Table I, our figures beside the printed ones, in
  two columns: *world-aligned* scans, the paper's own setting (its phase correlation estimates
  translation only, and its simulation hands it scans in world axes, so rotations never enter
  its images: the group scenarios are recorded a second time with ``scan_frame="world"`` and
  replayed through the paper's three estimators only, those of them ``--estimators`` selects,
  always driven by the scripted driver, outside the ranking), and the
  leaderboard's *sensor-frame* scans, where the paper's method cannot see the car turn;
* ``fig8_lidar_image.png`` (an eq.-5 Lidar image) and ``fig8_traces.png`` (per group, the true
  trace and every estimator's trace over the world map);
* ``maps.png``: the true map next to the occupancy maps built at the poses of the best-ranked
  estimator and of the paper's (``pc_pg``), in the first group with cylinders;
* ``failures.txt`` when an estimator raised (the others still run). An estimator that needs
  more Lidars than a log has (``pc_offset``, ``pc_pg`` on the one-laser ACES log:
  :attr:`estimators.base.Estimator.min_lidars`) is not run there and shows "n/a (needs 2
  Lidars)"; that is no failure.

Re-running with the same database skips everything already stored.

Cost grows as scenarios x steps x estimators. The default matrix (5 groups x 2 seeds, the
paper's full traces and the hallway out-and-back: 3,638 steps, plus the first 1,000 ACES scans)
costs, in CPU time, about 20 ms per step for all ten estimators together (``pc_fusion`` 4.8 ms,
``slam`` 2.9 ms, the rest 0-2.6 ms), about 5 ms per step for the map scores of all ten (the grid
and the obstacle tracker on every scan) and 3 s for the per-scenario map truths; Table I's
world-aligned copies of the six group scenarios add 2,108 steps through the three paper
estimators. About 126 CPU-seconds in all: 66 s on two free cores. The summary line prints the
workers' time per stage and their CPU time, so a slow run can be told apart from a busy machine.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from agents.driver import DRIVERS
from estimators.leaderboard.database import (
    DatabaseError,
    ExperimentDatabase,
    Scenario,
    TraceRecord,
    canonical_json,
    package_version,
)
from estimators.leaderboard.runner import (
    STAGES,
    EstimatorSpec,
    RealLog,
    RunInterrupted,
    SideRun,
    run_matrix,
)
from estimators.paths import SHARED_DATA
from estimators.registry import names


@dataclass(frozen=True)
class Group:
    """A column of the leaderboard: one world driven along one trace seed."""

    name: str
    world: str
    trace: str


#: The paper's three groups (Fig. 7) plus the straight seed and a drive that revisits a place.
#: The straight run goes through the hallway: motion along a corridor is the classic hard case
#: for scan matching. The out-and-back drive goes down that corridor and back along it, 2 m to
#: the left: the one default drive where loop closure (``slam``) can correct a front end.
DEFAULT_GROUPS: tuple[Group, ...] = (
    Group("G1 open+right_turn", "open_cylinders", "right_turn"),
    Group("G2 hallway+zigzag", "hallway", "zigzag"),
    Group("G3 closed-to-open+zigzag", "closed_to_open", "zigzag"),
    Group("hallway+straight", "hallway", "straight"),
    Group("hallway+out_and_back", "hallway", "out_and_back"),
)
#: A few seeds per group: each seed draws new range noise (and a new world for "random").
DEFAULT_SEEDS: tuple[int, ...] = (0, 1)
#: Range noise [m] of Table I's runs: 1 cm, a cheap time-of-flight Lidar.
DEFAULT_NOISE = 0.01


@dataclass(frozen=True)
class TableICase:
    """One row of the paper's Table I (section IV.C)."""

    case: int
    area: str
    feature: str
    pose_graph: bool
    world: str
    trace: str
    paper_accuracy: float
    estimator: str  # the paper's line colour: brown = offset Lidar only, blue = both + eq. 10


TABLE_I: tuple[TableICase, ...] = (
    TableICase(1, "open", "rich", False, "open_cylinders", "right_turn", 31.25, "pc_offset"),
    TableICase(2, "open", "rich", True, "open_cylinders", "right_turn", 91.10, "pc_pg"),
    TableICase(3, "close", "low", False, "hallway", "zigzag", 60.08, "pc_offset"),
    TableICase(4, "close", "low", True, "hallway", "zigzag", 60.31, "pc_pg"),
    TableICase(5, "close to open", "medium", False, "closed_to_open", "zigzag", 64.45,
               "pc_offset"),
    TableICase(6, "close to open", "medium", True, "closed_to_open", "zigzag", 63.54, "pc_pg"),
)
#: The paper's estimators: the only ones replayed on Table I's world-aligned recordings.
PAPER_ESTIMATORS: tuple[str, ...] = ("pc", "pc_offset", "pc_pg")
#: Table I's columns: env ``scan_frame`` -> title. World-aligned is the paper's setting.
TABLE_I_FRAMES: dict[str, str] = {"world": "world-aligned", "sensor": "sensor-frame"}
#: Who drives the world-aligned recordings, whatever ``--driver`` says: the paper's scripted
#: traces, and no learned policy (trained on sensor-frame scans) sees rotated inputs.
PAPER_DRIVER = "scripted"

#: (metric stored in the database, column title, lower is better)
METRIC_COLUMNS: tuple[tuple[str, str, bool], ...] = (
    ("accuracy_percent", "eq.-11 accuracy [%]", False),
    ("ate_rmse_m", "ATE [m]", True),
    ("heading_rmse_deg", "heading RMSE [deg]", True),
    ("drift_percent", "drift [%]", True),
    ("ms_per_step", "ms/step", True),
    ("map_iou", "map IoU", False),
    ("map_precision", "map precision", False),
    ("map_recall", "map recall", False),
    ("cylinder_recall", "cylinder recall", False),
    ("cylinder_error_m", "cylinder error [m]", True),
)
RANK_KEYS: dict[str, str] = {"ate": "ate_rmse_m", "accuracy": "accuracy_percent",
                             "heading": "heading_rmse_deg", "drift": "drift_percent",
                             "map": "map_iou"}
#: The paper's estimator, whose map ``maps.png`` shows next to the best one's.
PAPER_ESTIMATOR = "pc_pg"
REAL_METRIC = "relations_all_translation_m"
DATA_DIR = SHARED_DATA / "radish"
#: Scans of the ACES log replayed by default: the first ~2 minutes of the 7,374, enough for a
#: few hundred ground-truth relations while keeping the default run within a minute.
DEFAULT_REAL_SCANS = 1000


class OutputDirectoryError(OSError):
    """The output directory cannot be created or written."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="duallidar-leaderboard",
        description="Rank every registered estimator on recorded DualLidar-v0 scenarios, "
                    "reproduce the paper's Table I and draw its Fig. 8.",
    )
    parser.add_argument("--worlds", nargs="+", metavar="WORLD",
                        help="worlds to run (default: the paper's groups plus the straight "
                        "and out-and-back hallway drives)")
    parser.add_argument("--traces", nargs="+", metavar="TRACE",
                        help="trace seeds, crossed with --worlds (default: the paper's pairs)")
    parser.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS),
                        help="env seeds per scenario (default: %(default)s)")
    parser.add_argument("--driver", choices=sorted(DRIVERS), default="scripted",
                        help="who drives the recorded scenarios (default: %(default)s)")
    parser.add_argument("--estimators", nargs="+", metavar="NAME",
                        help="estimators to rank (default: every registered one)")
    parser.add_argument("--noise", type=float, default=DEFAULT_NOISE,
                        help="range noise std [m] (default: %(default)s, as in Table I)")
    parser.add_argument("--db", type=Path, default=None,
                        help="experiment database (default: OUT/experiments.sqlite)")
    parser.add_argument("--out", type=Path, default=Path("leaderboard"),
                        help="output directory (default: %(default)s)")
    parser.add_argument("--workers", type=int, default=2,
                        help="worker processes, parallel over scenarios; 1 = this process "
                             "(default: %(default)s)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the scenarios on this Dask scheduler (e.g. tcp://host:8786) "
                             "instead of local worker processes; needs dask.distributed")
    parser.add_argument("--rank-by", choices=sorted(RANK_KEYS), default="ate",
                        help="metric that orders the table (default: %(default)s)")
    parser.add_argument("--no-real", action="store_true",
                        help="skip the real-log (Radish ACES) results")
    parser.add_argument("--real-scans", type=int, default=DEFAULT_REAL_SCANS,
                        help="scans of the real log to replay, 0 = all (default: %(default)s)")
    parser.add_argument("--tum", action="store_true",
                        help="also write every trace of the run and its ground truth as TUM "
                             "files (OUT/tum/), for evo")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


def _check_names(parser: argparse.ArgumentParser, kind: str, given: Sequence[str],
                 valid: Sequence[str]) -> None:
    for name in given:
        if name not in valid:
            parser.error(f"unknown {kind} {name!r}: expected one of {', '.join(valid)}")


def build_groups(worlds: Sequence[str] | None, traces: Sequence[str] | None) -> list[Group]:
    """The scenario groups: the defaults, or ``worlds`` x ``traces`` (each defaulting to the
    paper's trace of the world / every world of the default groups)."""
    from lidar_env.worlds import PAPER_TRACES

    if worlds is None and traces is None:
        return list(DEFAULT_GROUPS)
    chosen_worlds = list(worlds) if worlds else list(dict.fromkeys(g.world for g in DEFAULT_GROUPS))
    return [
        Group(f"{world}+{trace}", world, trace)
        for world in chosen_worlds
        for trace in (traces or [PAPER_TRACES[world]])
    ]


def check_output_dir(out: Path) -> None:
    """Create ``out`` if needed and prove it writable, before any work is done."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as error:
        raise OutputDirectoryError(
            f"output directory {out} is not writable ({error.strerror}); "
            "choose another --out"
        ) from error


def _mean(values: list[float]) -> float:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def _fmt(value: float, digits: int = 2) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _current(records: list[TraceRecord], specs: Sequence[EstimatorSpec],
             version: str) -> dict[tuple[Scenario, str], TraceRecord]:
    """The records made by exactly the requested estimators, params and package version."""
    wanted = {spec.name: spec.resolved_params for spec in specs}
    return {
        (record.scenario, record.trace.estimator): record
        for record in records
        if record.trace.estimator in wanted
        and canonical_json(record.trace.params) == canonical_json(wanted[record.trace.estimator])
        and record.trace.package_version == version
    }


def rank_table(groups: Sequence[Group], scenarios: dict[str, list[Scenario]],
               specs: Sequence[EstimatorSpec], records: dict[tuple[Scenario, str], TraceRecord],
               real: Scenario | None, rank_key: str,
               real_not_applicable: Mapping[str, str] | None = None) -> list[dict[str, Any]]:
    """One row per estimator: metric means over every simulated scenario, per-group accuracy
    and ATE, the real-log relation error (or, in ``real_note``, why the estimator does not
    apply to the log: ``real_not_applicable`` maps its name to the reason); sorted best first
    (NaN last)."""
    rows = []
    for spec in specs:
        mine = [records[(s, spec.name)] for group in groups for s in scenarios[group.name]
                if (s, spec.name) in records]
        total = sum(len(scenarios[group.name]) for group in groups)
        row: dict[str, Any] = {"estimator": spec.name, "scenarios": len(mine),
                               "scenarios_run": total}
        for key, _, _ in METRIC_COLUMNS:
            row[key] = _mean([r.metrics.get(key, math.nan) for r in mine])
        for group in groups:
            in_group = [records[(s, spec.name)] for s in scenarios[group.name]
                        if (s, spec.name) in records]
            row[f"{group.name} accuracy_percent"] = _mean(
                [r.metrics.get("accuracy_percent", math.nan) for r in in_group])
            row[f"{group.name} ate_rmse_m"] = _mean(
                [r.metrics.get("ate_rmse_m", math.nan) for r in in_group])
        if real is not None:
            record = records.get((real, spec.name))
            row[REAL_METRIC] = math.nan if record is None else record.metrics.get(REAL_METRIC)
            row["real_note"] = (real_not_applicable or {}).get(spec.name, "")
        rows.append(row)
    lower_better = next(lower for key, _, lower in METRIC_COLUMNS if key == rank_key)

    def order(row: dict[str, Any]) -> tuple[bool, float]:
        value = row[rank_key]
        return (not math.isfinite(value), value if lower_better else -value)

    return sorted(rows, key=order)


def _markdown(header: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines) + "\n"


def leaderboard_markdown(rows: Sequence[dict[str, Any]], groups: Sequence[Group],
                         real_name: str | None) -> str:
    header = ["#", "estimator", *(title for _, title, _ in METRIC_COLUMNS)]
    header += [f"{g.name}: acc % / ATE m" for g in groups]
    if real_name:
        header.append(f"{real_name} rel. error [m]")
    body = []
    for rank, row in enumerate(rows, 1):
        name = row["estimator"]
        if row["scenarios"] < row["scenarios_run"]:  # means over fewer scenarios: say so
            name += f" (scored on {row['scenarios']} of {row['scenarios_run']})"
        cells = [str(rank), name]
        cells += [_fmt(row[key], 1 if key.endswith("percent") else 3) for key, _, _ in
                  METRIC_COLUMNS]
        cells += [f"{_fmt(row[f'{g.name} accuracy_percent'], 1)} / "
                  f"{_fmt(row[f'{g.name} ate_rmse_m'], 3)}" for g in groups]
        if real_name:
            note = row.get("real_note")
            cells.append(f"n/a ({note})" if note else _fmt(row.get(REAL_METRIC, math.nan), 3))
        body.append(cells)
    return _markdown(header, body)


def map_ceiling_note(records: dict[tuple[Scenario, str], TraceRecord]) -> str:
    """A line under the table: the map scores at the true poses (the mapper's own ceiling for
    the estimators' map columns), averaged over the scenarios like the columns."""
    per_scenario = {scenario: record.metrics for (scenario, _), record in records.items()
                    if "map_iou_true_poses" in record.metrics}
    if not per_scenario:
        return ""
    scores = []
    for key, title, _ in METRIC_COLUMNS:
        if key.startswith(("map_", "cylinder_")):
            mean = _mean([m.get(f"{key}_true_poses", math.nan) for m in per_scenario.values()])
            scores.append(f"{title} {_fmt(mean, 3)}")
    return f"\nMaps at the true poses (the mapper's ceiling): {', '.join(scores)}.\n"


def _seed_metrics(runs: Sequence[Scenario], estimator: str,
                  records: dict[tuple[Scenario, str], TraceRecord]) -> list[dict[str, float]]:
    return [records[(s, estimator)].metrics for s in runs if (s, estimator) in records]


def table_one(by_frame: Mapping[str, Mapping[tuple[str, str], Sequence[Scenario]]],
              records: dict[tuple[Scenario, str], TraceRecord]) -> list[dict[str, Any]]:
    """Table I: the paper's accuracy per case beside ours, for each scan frame of ``by_frame``
    (``"world"``/``"sensor"`` -> (world, trace) -> the scenarios, one per seed): the mean and
    std over seeds, the mean ATE, and, for the cases without pose-graph correlation, the
    main-Lidar-only ``pc`` as well (NaN where nothing ran)."""
    rows = []
    for case in TABLE_I:
        row: dict[str, Any] = {
            "case": case.case, "area": case.area, "feature": case.feature,
            "pose_graph": "yes" if case.pose_graph else "no",
            "scenario": f"{case.world}+{case.trace}", "estimator": case.estimator,
            "paper_accuracy_percent": case.paper_accuracy,
        }
        for frame in TABLE_I_FRAMES:
            runs = by_frame.get(frame, {}).get((case.world, case.trace), [])
            ours = _seed_metrics(runs, case.estimator, records)
            accuracy = [m["accuracy_percent"] for m in ours]
            main_only = [] if case.pose_graph else _seed_metrics(runs, "pc", records)
            row.update({
                f"ours_{frame}_accuracy_percent": _mean(accuracy),
                f"ours_{frame}_std_percent": float(np.std(accuracy)) if ours else math.nan,
                f"ours_{frame}_seeds": len(ours),
                f"ours_{frame}_ate_m": _mean([m.get("ate_rmse_m", math.nan) for m in ours]),
                f"pc_main_only_{frame}_accuracy_percent": _mean(
                    [m["accuracy_percent"] for m in main_only]),
            })
        rows.append(row)
    return rows


def table_one_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """Table I as markdown, with a legend of the two scan frames."""
    titles = list(TABLE_I_FRAMES.values())
    header = ["case", "area", "feature", "pose-graph", "scenario", "estimator", "paper [%]",
              *(f"ours, {title} [%] (mean ± std, seeds)" for title in titles),
              f"ATE {' / '.join(titles)} [m]", f"pc main only, {' / '.join(titles)} [%]"]
    body = []
    for r in rows:
        ours = [f"{_fmt(r[f'ours_{frame}_accuracy_percent'])} ± "
                f"{_fmt(r[f'ours_{frame}_std_percent'])} ({r[f'ours_{frame}_seeds']})"
                if r[f"ours_{frame}_seeds"] else "not run" for frame in TABLE_I_FRAMES]
        ate = " / ".join(_fmt(r[f"ours_{frame}_ate_m"], 3) for frame in TABLE_I_FRAMES)
        main_only = "" if r["pose_graph"] == "yes" else " / ".join(
            _fmt(r[f"pc_main_only_{frame}_accuracy_percent"]) for frame in TABLE_I_FRAMES)
        body.append([str(r["case"]), r["area"], r["feature"], r["pose_graph"], r["scenario"],
                     r["estimator"], f"{r['paper_accuracy_percent']:.2f}", *ours, ate,
                     main_only])
    legend = (
        "\nworld-aligned: the paper's setting, scans rotated into world axes (env "
        "`scan_frame=\"world\"`): the translation-only phase correlation never sees a rotation. "
        "sensor-frame: the scans as mounted Lidars give them (the leaderboard's scenarios), "
        "where the paper's method cannot see the car turn. Accuracy = 100% - eq. 11, floored "
        "at 0; ATE for context (eq. 11 ignores direction).\n"
    )
    return _markdown(header, body) + legend


def table_one_scenarios(groups: Sequence[Group], scenarios: Mapping[str, Sequence[Scenario]],
                        specs: Sequence[EstimatorSpec]
                        ) -> dict[str, dict[tuple[str, str], list[Scenario]]]:
    """Table I's scenarios per scan frame (:data:`TABLE_I_FRAMES`): the groups that are Table I
    cases as the leaderboard runs them (``"sensor"``), and the same scenarios with
    ``scan_frame="world"``, driven by :data:`PAPER_DRIVER` (``"world"``; none unless one of
    :data:`PAPER_ESTIMATORS` runs)."""
    cases = {(case.world, case.trace) for case in TABLE_I}
    sensor = {(g.world, g.trace): list(scenarios[g.name]) for g in groups
              if (g.world, g.trace) in cases}
    world: dict[tuple[str, str], list[Scenario]] = {}
    if any(spec.name in PAPER_ESTIMATORS for spec in specs):
        world = {pair: [replace(s, config={**s.config, "scan_frame": "world"},
                                driver=PAPER_DRIVER) for s in runs]
                 for pair, runs in sensor.items()}
    return {"world": world, "sensor": sensor}


def _write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


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


def _executor(args: argparse.Namespace) -> Any:
    """A Dask client when ``--scheduler`` is given, else a local process pool (``None`` for
    one worker: run in this process)."""
    if args.scheduler:
        from distributed import Client

        return Client(args.scheduler)
    return ProcessPoolExecutor(args.workers) if args.workers > 1 else None


def export_tum_files(db: ExperimentDatabase, records: dict[tuple[Scenario, str], TraceRecord],
                     directory: Path) -> Path:
    """``<scenario>_<estimator>.tum`` per trace and ``<scenario>_truth.tum`` per simulated
    scenario in ``directory``; returns it."""
    directory.mkdir(exist_ok=True)
    for (scenario, estimator), record in records.items():
        stem = scenario.label.replace("/", "_")
        db.export_tum(record.trace_id, directory / f"{stem}_{estimator}.tum")
        if scenario.kind == "sim" and not (directory / f"{stem}_truth.tum").exists():
            db.export_truth_tum(scenario, directory / f"{stem}_truth.tum")
    return directory


def _progress(total: int, label: str, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit="scenario", disable=not enabled, leave=False)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the leaderboard; returns the exit status (2 for bad input)."""
    from lidar_env.traces import TRACE_NAMES
    from lidar_env.worlds import WORLD_NAMES

    parser = _parser()
    args = parser.parse_args(argv)
    _check_names(parser, "world", args.worlds or [], WORLD_NAMES)
    _check_names(parser, "trace", args.traces or [], TRACE_NAMES)
    estimator_names = args.estimators or names()
    _check_names(parser, "estimator", estimator_names, names())
    if not estimator_names:
        parser.error("no estimators are registered")
    if args.workers < 1:
        parser.error(f"--workers: expected an integer >= 1, got {args.workers}")
    if not math.isfinite(args.noise) or args.noise < 0:
        parser.error(f"--noise: expected a range noise std >= 0 [m], got {args.noise}")
    if args.scheduler:
        try:
            import distributed  # noqa: F401
        except ImportError:
            parser.error("--scheduler needs dask.distributed: pip install 'duallidar[distributed]'")
    if args.real_scans < 0:
        parser.error(f"--real-scans: expected an integer >= 0, got {args.real_scans}")
    start = time.perf_counter()
    try:
        check_output_dir(args.out)
        db = ExperimentDatabase(args.db or args.out / "experiments.sqlite")
    except (OutputDirectoryError, DatabaseError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    with db:
        return _run(args, db, build_groups(args.worlds, args.traces),
                    [EstimatorSpec(name) for name in estimator_names], start)


def _run(args: argparse.Namespace, db: ExperimentDatabase, groups: list[Group],
         specs: list[EstimatorSpec], start: float) -> int:
    config = {"range_noise_std": args.noise}
    scenarios = {g.name: [Scenario(g.world, g.trace, seed, config, args.driver)
                          for seed in args.seeds]
                 for g in groups}
    logs = []
    if not args.no_real:
        log = RealLog("aces", str(DATA_DIR / "aces.clf.bz2"), str(DATA_DIR / "aces.relations"),
                      args.real_scans or None)
        if Path(log.log_path).exists() and Path(log.relations_path).exists():
            logs.append(log)
        else:
            print(f"note: real-log results skipped: {DATA_DIR} has no ACES log and relations")
    table_i_runs = table_one_scenarios(groups, scenarios, specs)
    world_aligned = SideRun(
        tuple(s for runs in table_i_runs["world"].values() for s in runs),
        tuple(spec for spec in specs if spec.name in PAPER_ESTIMATORS))
    executor = _executor(args)
    try:
        every = [s for group in groups for s in scenarios[group.name]]
        tasks = len(every) + len(world_aligned.scenarios) + len(logs) * len(specs)
        with _progress(tasks, "scenarios", not args.no_progress) as bar:
            summary = run_matrix(db, every, logs, specs, executor, side_runs=[world_aligned],
                                 on_done=lambda _: bar.update())
    except RunInterrupted as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    finally:
        if isinstance(executor, ProcessPoolExecutor):
            executor.shutdown(cancel_futures=True)
        elif executor is not None:
            executor.close()  # a Dask client: disconnect, the cluster stays up

    reporting = time.perf_counter()
    records = _current(db.traces(poses=False), specs, package_version())
    real = logs[0].scenario if logs else None
    not_applicable = {spec.name: reason for spec in specs
                      if logs and (reason := spec.not_applicable(logs[0].n_lidars))}
    rows = rank_table(groups, scenarios, specs, records, real, RANK_KEYS[args.rank_by],
                      not_applicable)
    out: Path = args.out
    table = leaderboard_markdown(rows, groups, "ACES" if real else None)
    table += map_ceiling_note(records)
    case_rows = table_one(table_i_runs, records)
    written = [out / "leaderboard.md", out / "leaderboard.csv", out / "results.csv"]
    (out / "leaderboard.md").write_text(
        f"# duallidar leaderboard (ranked by {args.rank_by}; noise {args.noise} m; seeds "
        f"{', '.join(map(str, args.seeds))})\n\n{table}")
    _write_csv(out / "leaderboard.csv", rows)
    _write_csv(out / "results.csv", [
        {"estimator": name, "kind": scenario.kind, "world": scenario.world,
         "trace": scenario.trace, "seed": scenario.seed,
         "scan_frame": scenario.config.get("scan_frame", "sensor"), **record.metrics}
        for (scenario, name), record in records.items()
    ])
    print(table)
    if table_i_runs["sensor"]:
        table_i = table_one_markdown(case_rows)
        (out / "table1.md").write_text(
            f"# Table I: eq.-11 accuracy, paper vs ours (noise {args.noise} m; seeds "
            f"{', '.join(map(str, args.seeds))}; driver {args.driver}, world-aligned runs "
            f"{PAPER_DRIVER})\n\n{table_i}")
        _write_csv(out / "table1.csv", case_rows)
        written += [out / "table1.md", out / "table1.csv"]
        print("Table I (accuracy = 100% - eq. 11):\n" + table_i)
    else:
        print("note: Table I skipped: the run holds none of the paper's world/trace pairs")
    try:
        written += draw_figure_8(db, groups, scenarios, records, specs, out)
        written += draw_map_figure(db, groups, scenarios, records,
                                   [row["estimator"] for row in rows], out)
    except ImportError as error:
        print(f"note: Fig. 8 skipped ({error}); install the plots extra: "
              "pip install 'duallidar[plots]'")
    if args.tum:
        written.append(export_tum_files(db, records, out / "tum"))
    failures = summary.failures
    if failures:
        (out / "failures.txt").write_text(
            "".join(f"== {stage}\n{error}\n" for stage, error in failures.items()))
        written.append(out / "failures.txt")
        print(f"note: {len(failures)} estimator runs failed: {', '.join(sorted(failures))}")
    else:  # a failures.txt of an earlier run in this directory no longer holds
        (out / "failures.txt").unlink(missing_ok=True)
    if summary.not_applicable:
        print("note: not applicable, so not run: " + ", ".join(
            f"{stage} ({reason})" for stage, reason in sorted(summary.not_applicable.items())))
    done = summary.recorded, summary.traces
    skipped = summary.skipped
    stages = summary.stage_seconds
    print("worker time: " + ", ".join(f"{stage} {stages[stage]:.1f} s" for stage in STAGES
                                       if stage in stages)
          + f"; workers' CPU time {summary.cpu_seconds:.1f} s; tables and figures "
            f"{time.perf_counter() - reporting:.1f} s")
    side = (f" + {len(world_aligned.estimators)} x {len(world_aligned.scenarios)} world-aligned "
            "for Table I" if world_aligned.scenarios else "")
    print(f"leaderboard: {len(specs)} estimators x {len(every)} scenarios{side}"
          f"{' + ' + str(len(logs)) + ' real log' if logs else ''} in "
          f"{time.perf_counter() - start:.1f} s ({done[0]} recorded, {done[1]} traces new, "
          f"{skipped} already stored); database {db.path}; files in {out}/: "
          f"{', '.join(p.name for p in written)}")
    unrecorded = [stage for stage in failures if stage.endswith(": record")]
    if unrecorded:  # an estimator may legitimately not apply; a scenario must record
        print(f"error: {len(unrecorded)} scenarios could not be recorded (see failures.txt)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
