"""The paper's method, eqs. 4-11: the eq. 4 scan filter and eq. 5 scan image (``scan_image``),
eq. 6-9 FFT phase correlation (``phase_correlation``), eq. 10 four-node pose-graph correlation
(``pose_graph_correlation``) and the estimators built from them, ``zero``, ``pc``, ``pc_offset``
and ``pc_pg`` (``pc``). The bottom layer: it imports only ``estimators.base`` and ``lidar_env``.
"""

from estimators.paper.pc import PhaseCorrelationOdometry, PoseGraphCorrelationOdometry, ZeroMotion
from estimators.paper.phase_correlation import phase_correlate
from estimators.paper.pose_graph_correlation import pose_graph_correlation
from estimators.paper.scan_image import scan_to_image

__all__ = [
    "PhaseCorrelationOdometry",
    "PoseGraphCorrelationOdometry",
    "ZeroMotion",
    "phase_correlate",
    "pose_graph_correlation",
    "scan_to_image",
]
