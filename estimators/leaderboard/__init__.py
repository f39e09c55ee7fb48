"""The leaderboard pipeline, the top layer: recording scenarios and replaying them through
estimators (``recording``), the SQLite experiment database (``database``), the scenario runner
over any executor (``runner``) and the command line (``cli``: ``duallidar leaderboard``,
``duallidar-leaderboard``, ``python -m estimators.leaderboard``), and ``duallidar run``: any
estimator over one recording, scored on its truth (``run_cli``, ``run_sources``, ``single_run``,
``run_outputs``). It may import every other part of ``estimators``; nothing imports it.
"""

from estimators.leaderboard.cli import main
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.recording import record, replay
from estimators.leaderboard.records import Scenario
from estimators.leaderboard.runner import run_matrix, run_scenarios

__all__ = ["ExperimentDatabase", "Scenario", "main", "record", "replay", "run_matrix",
           "run_scenarios"]
