"""What the leaderboard command draws and publishes after the tables: every figure
(:func:`draw_all`: the report's lead traces, Fig. 8, the maps, error over distance, the
real-log relation errors, cost against accuracy), the self-contained ``report.html`` of the run
(:func:`publish_report`) and what the terminal shows at the end (:func:`terminal_summary`: the
lead paragraph, the headline table and the files written).
"""

from __future__ import annotations

import shlex
import textwrap
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.figures import draw_figure_8, draw_lead_figure, draw_map_figure
from estimators.leaderboard.matrix import Group
from estimators.leaderboard.plots import (
    draw_relation_histograms,
    draw_segment_errors,
    draw_speed_accuracy,
    relation_error_samples,
)
from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.report import split_board, write_report
from estimators.leaderboard.settings import describe_settings
from estimators.leaderboard.tasks import EstimatorSpec
from estimators.leaderboard.workers import process_pool

#: The report's first figure, shown beside the headline table.
LEAD_FIGURE = "lead_traces.png"
#: Each figure's caption in the report, by file name, in the report's order.
CAPTIONS: dict[str, str] = {
    LEAD_FIGURE: "One group's run (its first seed): every estimator's trace over the "
                       "world, zoomed on the drive (truth black), and its position error over "
                       "the distance travelled (log scale). All groups: Fig. 8 below.",
    "fig8_traces.png": "Fig. 8: every estimator's trace over the map (truth black) and its "
                       "position error over the distance travelled, one run per group.",
    "fig8_lidar_image.png": "Fig. 8: the eq.-5 image of one scan, sensor frame, cropped to "
                            "the scan's extent.",
    "maps.png": "Occupancy maps: the true map and the maps built at the best estimator's and "
                "the paper estimator's poses.",
    "segment_errors.png": "Relative error over segments of growing length (KITTI-style).",
    "speed_accuracy.png": "Cost against accuracy, one point per estimator.",
    "relation_errors.png": "Real log: the distribution of each estimator's relation errors.",
}


def draw_all(db: ExperimentDatabase, groups: Sequence[Group],
             scenarios: dict[str, list[Scenario]],
             records: dict[tuple[Scenario, str], TraceRecord], specs: Sequence[EstimatorSpec],
             rows: Sequence[Mapping[str, Any]], logs: Sequence[RealLog], out: Path,
             workers: int = 1) -> list[Path]:
    """Every figure of the run into ``out`` (PNG + SVG each); returns the files written, in
    the same order whatever ``workers``: with more than one, the figures are drawn by that many
    processes at once (each opens the database again, read only; a figure takes 1-4 s, most of
    it matplotlib's PNG and SVG rendering). Raises ImportError without matplotlib."""
    import matplotlib  # noqa: F401  (fail early, with the caller's hint, when it is missing)

    names = [spec.name for spec in specs]
    ranked = [row["estimator"] for row in rows]
    every = [s for group in groups for s in scenarios[group.name]]
    jobs: list[tuple[Callable[..., list[Path]], bool, tuple[Any, ...]]] = [  # (draw, db?, args)
        (draw_lead_figure, True, (groups, scenarios, records, ranked, out)),
        (draw_figure_8, True, (groups, scenarios, records, specs, out)),
        (draw_map_figure, True, (groups, scenarios, records, ranked, out)),
        (draw_segment_errors, True, (every, names, records, out)),
        (draw_speed_accuracy, False, (list(rows), out)),
    ]
    for log in logs[:1]:
        samples = relation_error_samples(db, log.scenario, log.relations(), names, records)
        jobs.append((draw_relation_histograms, False, (samples, log.name.upper(), out)))
    if workers <= 1:
        return [path for draw, with_db, args in jobs
                for path in (draw(db, *args) if with_db else draw(*args))]
    with process_pool(min(workers, len(jobs))) as pool:
        futures = [pool.submit(_draw, draw, db.path if with_db else None, args)
                   for draw, with_db, args in jobs]
        return [path for future in futures for path in future.result()]


def _draw(draw: Callable[..., list[Path]], db_path: Path | None,
          args: tuple[Any, ...]) -> list[Path]:
    """One figure job in a worker process: ``draw(db, *args)`` on the database at ``db_path``
    opened again (``draw(*args)`` without one)."""
    if db_path is None:
        return draw(*args)
    with ExperimentDatabase(db_path, verify=False) as db:
        return draw(db, *args)


def publish_report(out: Path, written: Sequence[Path], config: Mapping[str, object],
                   argv: Sequence[str]) -> Path:
    """``out/report.html`` from the tables and PNG figures this run wrote (``written``):
    ``leaderboard.md``, ``table1.md`` when written, the lead figure beside the headline table
    and the other figures in :data:`CAPTIONS` order; ``config``: the parsed command line
    (``vars(args)``), shown as option/value rows; ``argv``: the arguments that reproduce it."""
    names = {path.name for path in written}
    board = (out / "leaderboard.md").read_text(encoding="utf-8")
    title, _, board = board.partition("\n")
    table_one = None
    if "table1.md" in names:
        table_one = (out / "table1.md").read_text(encoding="utf-8").partition("\n")[2]
    figures = {out / name: caption for name, caption in CAPTIONS.items()
               if name in names and name != LEAD_FIGURE}
    lead = (out / LEAD_FIGURE, CAPTIONS[LEAD_FIGURE]) if LEAD_FIGURE in names else None
    command = shlex.join(["python", "-m", "estimators.leaderboard", *argv])
    return write_report(out / "report.html", title=title.lstrip("# "), board=board,
                        table_one=table_one, figures=figures,
                        settings=describe_settings(config), command=command, lead_figure=lead)


def terminal_summary(out: Path, written: Sequence[Path], width: int = 100) -> str:
    """What the leaderboard prints when done: the title and lead paragraph of ``out``'s
    ``leaderboard.md`` (wrapped to ``width`` characters), its headline table, and where the
    files of ``written`` are: the report first, then the tables, figures (PNG; an SVG beside
    each) and the rest."""
    title, _, board = (out / "leaderboard.md").read_text(encoding="utf-8").partition("\n")
    parts = split_board(board)
    kinds: dict[str, list[str]] = {"tables": [], "figures": [], "other": []}
    for path in written:
        if path.name == "report.html" or path.suffix == ".svg":
            continue
        kind = ("tables" if path.suffix in (".md", ".csv") else
                "figures" if path.suffix == ".png" else "other")
        kinds[kind].append(path.name if path.parent == out else str(path))
    lead = textwrap.fill(parts.lead, width, break_on_hyphens=False)
    lines = [title.lstrip("# "), "", lead, "", parts.table, ""]
    if (out / "report.html") in written:
        lines.append(f"report:  {out / 'report.html'}  (every table and figure)")
    lines += [f"{kind + ':':8} in {out}/: {', '.join(files)}"
              for kind, files in kinds.items() if files]
    return "\n".join(lines)
