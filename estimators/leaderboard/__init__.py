"""The leaderboard pipeline, the top layer: recording scenarios and replaying them through
estimators (``recording``), the SQLite experiment database (``database``), the scenario runner
over any executor (``runner``) and the command line (``cli``: ``duallidar-leaderboard``,
``python -m estimators.leaderboard``). It may import every other part of ``estimators``;
nothing imports it.
"""

from estimators.leaderboard.cli import main
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.recording import record, replay
from estimators.leaderboard.records import Scenario
from estimators.leaderboard.runner import run_matrix, run_scenarios

__all__ = ["ExperimentDatabase", "Scenario", "main", "record", "replay", "run_matrix",
           "run_scenarios"]
