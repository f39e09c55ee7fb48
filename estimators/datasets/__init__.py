"""Real Lidar data: the CARMEN log reader (``carmen``), the ROS bag reader and writer
(``rosbag_reader``, ``rosbag_writer``, K Lidars as a :class:`Recording`), and the runner that
drives an estimator over a recording and scores it by relations (``real_log``). It imports
``estimators.base``, ``estimators.evaluation`` and ``lidar_env``.
"""

from estimators.datasets.carmen import CarmenFormatError, CarmenLog, load_log
from estimators.datasets.real_log import run_on_log, score_relations
from estimators.datasets.recording import Recording
from estimators.datasets.rosbag_reader import load_bag
from estimators.datasets.rosbag_writer import write_bag

__all__ = ["CarmenFormatError", "CarmenLog", "Recording", "load_bag", "load_log", "run_on_log",
           "score_relations", "write_bag"]
