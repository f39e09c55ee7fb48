"""A scan-to-scan check of ``lidar_odometry``'s map match: the rotation the scans themselves show.

The map match picks the pose that explains the largest share of the scan. Where the map
explains only half of it (a room coming into view in a fast turn, people in the way, a log's
burst of stamps), a wider search can find a wrong pose that explains a few points more: down
a corridor seen by a 180-degree Lidar, the car turned round by 180 degrees fits the two walls
about as well, and the all-headings fallback
(:func:`estimators.odometry.far_scans.fallback_match`) takes it for a few points more, while
the scan matched to the previous scan explains far more of it and shows no such turn.

So a map match that a search placed, or that leaves part of its scan unexplained
(``estimators.odometry.far_scans.CHECKED_BELOW``), is also matched to the previous scan
(PL-ICP from the constant-velocity
increment, :func:`estimators.matching.icp.match_scans`). Where the two turn the car by more
than ``tolerance`` apart, the map match is run again from the previous pose composed with the
scan-to-scan increment, and of the two map matches the one whose turn agrees with the match
that explains the larger share of its scan is kept: a map match explaining more of its scan
than the scan-to-scan match does of its own (a well-seen map, a scan-to-scan match thrown by
new surfaces) stands; a poorly explained one gives way to a consistent one. The two
scan matches are independent evidence, so a turn both agree on outweighs a few more points
explained on the map alone. Distances [m], angles [rad].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.matching.icp import ICPParams, MatchResult, match_scans, register
from estimators.matching.point_to_line import PointToLineReference
from lidar_env.core.se2 import compose, relative, wrap_angle

FloatArray = NDArray[np.float64]

#: [rad] turns of the map match and the scan-to-scan match further apart than this disagree:
#: several times the heading error of either match on a well-seen scan (0.1-1 deg), below
#: the 10-degree gross errors the check is for.
DEFAULT_TOLERANCE = np.radians(5.0)
#: Fewest points on either scan for a scan-to-scan match (fewer can fit anything).
MIN_POINTS = 10


@dataclass(frozen=True)
class CheckedMatch:
    """The map match kept (``result``), the scan-to-scan increment (``scan_match``, None when
    either scan had too few points) and whether the check replaced the map match."""

    result: MatchResult
    scan_match: MatchResult | None
    replaced: bool


def turn_between(previous: FloatArray, pose: FloatArray) -> float:
    """The turn [rad] from ``previous`` (3,) to ``pose`` (3,), wrapped to (-pi, pi]."""
    return float(wrap_angle(relative(previous, pose)[2]))


def check_against_scan(
    result: MatchResult, reference: PointToLineReference, points: FloatArray,
    previous_points: FloatArray | None, previous_pose: FloatArray, predicted: FloatArray,
    params: ICPParams, prior_pose: FloatArray, prior_information: FloatArray,
    min_quality: float, tolerance: float = DEFAULT_TOLERANCE,
) -> CheckedMatch:
    """``result``, the map match of ``points`` (M, 2, car frame), checked against the match of
    ``points`` to ``previous_points`` (car frame of the scan at ``previous_pose``) from the
    ``predicted`` increment (3,). The map match is run again from the scan-to-scan pose (held
    by the prior ``prior_information`` at ``prior_pose``, as the first was) where the turns
    differ by more than ``tolerance``, and kept when its turn agrees with the scan-to-scan one,
    the scan-to-scan match explains at least ``min_quality`` of the scan and more of it than
    ``result`` explains of the map (module docstring)."""
    if previous_points is None or min(len(previous_points), len(points)) < MIN_POINTS:
        return CheckedMatch(result, None, False)
    scan_match = match_scans(previous_points, points, predicted, params)
    scan_turn = float(scan_match.pose[2])
    if abs(wrap_angle(turn_between(previous_pose, result.pose) - scan_turn)) <= tolerance:
        return CheckedMatch(result, scan_match, False)
    if scan_match.quality < max(min_quality, result.quality):
        return CheckedMatch(result, scan_match, False)
    seeded = register(reference, points, compose(previous_pose, scan_match.pose), params,
                      prior_pose, prior_information)
    if abs(wrap_angle(turn_between(previous_pose, seeded.pose) - scan_turn)) > tolerance:
        return CheckedMatch(result, scan_match, False)
    return CheckedMatch(seeded, scan_match, True)
