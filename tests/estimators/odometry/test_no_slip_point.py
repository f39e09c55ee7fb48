"""The no-slip point found online (``estimators.odometry.no_slip_point``): a frame ahead of a
wheeled robot's axle is placed, a base that strafes or slides is refused, a step the scan does
not pin across the car is not used, the compiled step and fit give the numbers of their numpy
form bit for bit; and the constraint with that offset (``motion_prior.no_sideslip_prior``)."""

from __future__ import annotations

import math

import numpy as np

from estimators.odometry import no_slip_point
from estimators.odometry.local_map import LocalMapOdometry
from estimators.odometry.motion_prior import no_sideslip_prior
from estimators.odometry.no_slip_point import (
    MIN_TURNING_STEPS,
    NoSlipCalibration,
    NoSlipFit,
    _added,
    _sum,
    fitted,
)
from lidar_env.core.se2 import compose, relative

#: A well-seen step's information (3, 3): 100 points' worth across x and y, 1000 in heading.
SEEN = np.diag([100.0, 100.0, 1000.0])


def _steps(offset: float, n: int, seed: int, strafe: float = 0.0,
           slide: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Increments (n, 3) of a frame ``offset`` [m] ahead of a unicycle's axle driving 0.2 m
    steps turning up to 15 degrees, with 2 mm of registration noise; ``strafe`` [m] of random
    sideways motion (a holonomic base) in a third of the steps, up to twice ``slide`` [m] of
    sideways motion per radian of turn, at random (a skid-steered base on a floor whose grip
    varies), and the start headings (n,) [rad]."""
    rng = np.random.default_rng(seed)
    mount = np.array([offset, 0.0, 0.0])
    axle, increments, headings = np.zeros(3), [], []
    for k in range(n):
        turn = math.radians(15.0) * math.sin(0.3 * k) if k % 2 else 0.0
        chord = np.array([0.2 * math.cos(0.5 * turn), 0.2 * math.sin(0.5 * turn), turn])
        sideways = slide * turn * rng.uniform(0.0, 2.0) + (
            strafe * rng.normal() if k % 3 == 0 else 0.0)
        moved = compose(axle, chord + np.array([-math.sin(0.5 * turn) * sideways,
                                                math.cos(0.5 * turn) * sideways, 0.0]))
        increment = relative(compose(axle, mount), compose(moved, mount))
        increments.append(increment + np.array([*rng.normal(0.0, 0.002, 2), 0.0]))
        headings.append(float(axle[2]))
        axle = moved
    return np.array(increments), np.array(headings)


def _calibrated(offset: float, seed: int = 0, **motion: float) -> NoSlipCalibration:
    calibration = NoSlipCalibration()
    for increment, heading in zip(*_steps(offset, 200, seed, **motion), strict=True):
        calibration.add(increment, heading, SEEN)
    return calibration


def test_a_lidar_ahead_of_the_axle_is_placed_within_its_error() -> None:
    for offset, seed in ((0.0, 0), (0.3, 1), (-0.15, 2)):
        fit = _calibrated(offset, seed).fit
        assert fit is not None
        assert abs(fit.offset - offset) < max(3.0 * fit.offset_error, 1e-3)
        assert fit.offset_error < 0.01
        assert abs(fit.lateral(0.2) - 2.0 * offset * math.sin(0.1)) < 0.003


def test_a_base_that_strafes_or_slides_is_refused() -> None:
    assert _calibrated(0.1, strafe=0.03).fit is None  # strafes a third of the time
    assert _calibrated(0.1, slide=0.2).fit is None  # slides by up to 0.4 m per radian
    # (a slide in proportion to the turn moves the no-slip point: the fit places it there)


def test_steps_the_scan_does_not_pin_across_the_car_are_not_used() -> None:
    # a corridor along the world's x axis pins y and heading only; a car turned 30 degrees
    # towards the wall moves across itself partly along the axis
    corridor = np.diag([0.1, 100.0, 1000.0])
    increments, _ = _steps(0.0, 200, 0)
    calibration = NoSlipCalibration()
    for increment in increments:
        calibration.add(increment, math.radians(30.0), corridor)
    assert calibration.fit is None and len(calibration.steps) == 0
    for increment in increments:  # heading along the axis: across the car is what it pins
        calibration.add(increment, 0.0, corridor)
    assert calibration.fit is not None


def test_a_fit_needs_turning_steps_and_survives_a_restart() -> None:
    calibration = NoSlipCalibration()
    straight = np.array([0.2, 0.0, 0.0])
    for _ in range(100):
        calibration.add(straight, 0.0, SEEN)
    assert calibration.fit is None  # no turn: the offset is unknown
    calibration = _calibrated(0.2)
    fit = calibration.fit
    calibration.restart()
    for _ in range(MIN_TURNING_STEPS):
        calibration.add(straight, 0.0, SEEN)
    assert calibration.fit is fit  # too few turns to judge it again


def test_fitted_weighs_each_step_by_its_own_spread() -> None:
    increments, _ = _steps(0.2, 200, 3)
    steps = []
    for x, y, turn in increments:
        c, s = math.cos(0.5 * turn), math.sin(0.5 * turn)
        steps.append((c * x + s * y, c * y - s * x, 2.0 * s, 0.01))
    steps = np.array(steps)
    steps[::10, 1] += 0.5  # every tenth step a wrong match, seen as well as the rest
    fit = fitted(steps)
    assert fit is not None and abs(fit.offset - 0.2) < 0.01


def test_the_constraint_with_an_offset_holds_the_frame_to_its_sideways_step() -> None:
    previous = np.array([1.0, 2.0, 0.3])
    offset = 0.3
    pose = compose(previous, np.array([0.2, 0.02, 0.2]))  # a match slipped by 2 cm
    guess = compose(previous, np.array([0.25, 0.0, 0.2]))
    # the heading held by the prior: the centre moves sideways onto the constraint
    centre, information = no_sideslip_prior(np.array([0.4, 0.4, 1e6]), guess, previous,
                                            pose, 1e8, offset)
    np.testing.assert_allclose(information, information.T)
    step = relative(previous, centre)
    c, s = math.cos(0.5 * step[2]), math.sin(0.5 * step[2])
    lateral = c * step[1] - s * step[0]
    assert abs(step[2] - 0.2) < 1e-3
    assert abs(lateral - 2.0 * offset * math.sin(0.5 * step[2])) < 1e-4
    assert abs(lateral) > 0.05  # 0.3 m ahead of the axle, 0.2 rad: 6 cm sideways


def test_a_known_no_slip_point_keeps_its_own_slip() -> None:
    known = LocalMapOdometry(sideslip_sigma=2e-3)
    known._reset_motion_model()
    fit = known._no_slip_fit()
    assert fit is not None and fit.offset == 0.0 and fit.offset_error == 0.0
    assert known._sideslip() == 2e-3
    assert LocalMapOdometry()._sideslip() == 6e-4
    off = LocalMapOdometry(calibrated_sideslip_sigma=float("inf"))
    off._reset_motion_model()
    off._no_slip.fit = _calibrated(0.1).fit  # found, but not to be used
    assert off._no_slip_fit() is None


def _plain_variance(information: np.ndarray, heading: float) -> float:
    """The sideways variance [1 / points] of a step across ``heading`` [rad], by numpy."""
    try:
        covariance = np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return math.inf
    n = np.array([-math.sin(heading), math.cos(heading)])
    return float(n @ covariance[:2, :2] @ n)


def _plain_fitted(steps: np.ndarray) -> NoSlipFit | None:
    """:func:`fitted` in numpy array operations."""
    forward, lateral, chord, variance = steps.T
    precision = 1.0 / variance
    if not np.any(np.abs(chord) > no_slip_point.MIN_CHORD):
        return None
    weights = precision.copy()
    offset = scale = 0.0
    for _ in range(no_slip_point.ITERATIONS):
        offset = float(np.sum(weights * chord * lateral) / np.sum(weights * chord**2))
        normalised = (lateral - offset * chord) * np.sqrt(precision)
        scale = 1.4826 * float(np.median(np.abs(normalised)))
        if scale <= 0:
            return None
        weights = precision / (1.0 + (normalised / (no_slip_point.CAUCHY_SCALE * scale)) ** 2)
    inliers = np.abs(normalised) <= no_slip_point.OUTLIER * scale
    error = scale / math.sqrt(float(np.sum(weights * chord**2)))
    residual = scale * math.sqrt(float(np.median(variance)))
    if (error > no_slip_point.MAX_OFFSET_ERROR
            or residual > no_slip_point.MAX_SIDESLIP_SHARE * float(np.median(np.abs(forward)))
            or 1.0 - np.mean(inliers) > no_slip_point.MAX_OUTLIER_SHARE):
        return None
    return NoSlipFit(offset, error, residual)


def test_the_compiled_step_and_fit_are_their_numpy_form_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    for n in (1, 7, 8, 9, 127, 128, 129, 300, 400, 1000):
        values = rng.normal(size=n) * rng.choice([1e-6, 1.0, 1e6], size=n)
        assert _sum(values) == np.sum(values)
    assert math.copysign(1.0, _sum(np.full(20, -0.0))) == 1.0
    ring = np.zeros((1, 4))
    for _ in range(2000):
        root = rng.normal(size=(3, 3)) * rng.choice([1e-2, 1.0, 30.0], size=(3, 3))
        information = root @ root.T if rng.random() < 0.8 else np.diag([0.0, 1.0, 1.0])
        increment, heading = rng.normal(0.0, 0.3, 3), rng.uniform(-4.0, 4.0)
        variance = _plain_variance(information, heading + 0.5 * increment[2])
        pinned = 0 < variance <= 1.0 / no_slip_point.MIN_STEP_INFORMATION
        assert _added(ring, 0, increment, heading, information) == pinned
        assert not pinned or ring[0, 3] == variance
    assert not _added(ring, 0, np.zeros(3), 0.0, np.diag([np.inf, 100.0, 100.0]))  # no match
    for seed, offset, motion in ((0, 0.2, {}), (1, -0.1, {"strafe": 0.03}),
                                 (2, 0.3, {"slide": 0.2}), (3, 0.0, {})):
        increments, _ = _steps(offset, 400, seed, **motion)
        c, s = np.cos(0.5 * increments[:, 2]), np.sin(0.5 * increments[:, 2])
        steps = np.column_stack([c * increments[:, 0] + s * increments[:, 1],
                                 c * increments[:, 1] - s * increments[:, 0], 2.0 * s,
                                 rng.uniform(0.002, 0.2, len(increments))])
        for n in (12, 131, 400):
            assert fitted(steps[:n]) == _plain_fitted(steps[:n])
