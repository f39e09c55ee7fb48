"""Real Lidar data: the CARMEN log reader (``carmen``) and the runner that drives an estimator over
a log and scores it by relations (``real_log``). It imports ``estimators.base``,
``estimators.evaluation`` and ``lidar_env``.
"""

from estimators.datasets.carmen import CarmenFormatError, CarmenLog, load_log
from estimators.datasets.real_log import run_on_log, score_relations

__all__ = ["CarmenFormatError", "CarmenLog", "load_log", "run_on_log", "score_relations"]
