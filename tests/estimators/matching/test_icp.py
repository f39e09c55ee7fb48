"""Point-to-line ICP: the Gauss-Newton step against scipy, known poses recovered from
ray-cast scans, the ``icp`` estimator on a scan sequence, and readable errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from estimators import SensorSetup, make
from estimators.matching.icp import ICPParams, match_scans, register
from estimators.matching.match_result import MatchResult
from estimators.matching.point_to_line import (
    PointToLineReference,
    gauss_newton_step,
    point_to_line_jacobian,
    robust_weights,
)
from estimators.matching.scan_matching import scan_to_points, voxel_downsample
from lidar_env.core import ConfigError
from lidar_env.core.se2 import compose, inverse, relative, transform_points, wrap_angle

#: An L-shaped room with a pillar-like box: walls as segments (x1, y1, x2, y2) [m].
ROOM = np.array(
    [
        [-4.0, -3.0, 6.0, -3.0], [6.0, -3.0, 6.0, 1.0], [6.0, 1.0, 2.0, 1.0],
        [2.0, 1.0, 2.0, 4.0], [2.0, 4.0, -4.0, 4.0], [-4.0, 4.0, -4.0, -3.0],
        [-1.0, -0.5, 0.0, -0.5], [0.0, -0.5, 0.0, 0.5], [0.0, 0.5, -1.0, 0.5],
        [-1.0, 0.5, -1.0, -0.5],
    ]
)
ANGLES = np.radians(np.arange(-90.0, 90.0, 1.0))


def ray_cast(pose: np.ndarray, angles: np.ndarray = ANGLES, noise: float = 0.0,
             rng: np.random.Generator | None = None, max_range: float = 20.0) -> np.ndarray:
    """Ranges [m] from ``pose`` to the nearest wall of ROOM along each beam (exact, vectorised
    ray-segment intersection), plus Gaussian noise."""
    directions = np.column_stack([np.cos(pose[2] + angles), np.sin(pose[2] + angles)])
    start, end = ROOM[:, :2], ROOM[:, 2:]
    edge = end - start
    offset = (start - pose[:2])[None, :, :]
    d = directions[:, None, :]

    def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    cross = cross2(d, edge[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross2(offset, edge[None, :, :]) / cross
        u = cross2(offset, d) / cross
    hit = (np.abs(cross) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    ranges = np.where(hit, t, np.inf).min(axis=1)
    if noise:
        ranges = ranges + noise * rng.standard_normal(len(ranges))
    return np.minimum(ranges, max_range)


def points_at(pose: np.ndarray, **kwargs) -> np.ndarray:
    return scan_to_points(ray_cast(pose, **kwargs), ANGLES, 20.0)


def test_gauss_newton_step_matches_scipy_least_squares_with_cauchy_loss():
    rng = np.random.default_rng(3)
    anchors = rng.uniform(-5, 5, (60, 2))
    normals = rng.standard_normal((60, 2))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    query = anchors + rng.normal(0, 0.02, (60, 2))
    query[:6] += 0.5  # outliers the robust loss must discount
    truth = np.array([0.05, -0.03, 0.02])
    query = transform_points(inverse(truth), query)

    def residuals(pose: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", transform_points(pose, query) - anchors, normals)

    scale = 0.1
    oracle = least_squares(residuals, np.zeros(3), loss="cauchy", f_scale=scale, xtol=1e-12).x
    pose = np.zeros(3)
    for _ in range(50):  # IRLS with fixed pairs converges to the M-estimate
        moved = transform_points(pose, query)
        r = residuals(pose)
        jacobian = point_to_line_jacobian(moved, pose[:2], normals)
        pose = pose + gauss_newton_step(jacobian, r, robust_weights(r, "cauchy", scale))
    np.testing.assert_allclose(pose, oracle, atol=1e-6)


def test_prior_holds_the_unconstrained_direction():
    # One wall (normal along y): x and heading about the wall are free but for the prior.
    anchors = np.column_stack([np.linspace(-3, 3, 50), np.ones(50)])
    normals = np.tile([0.0, 1.0], (50, 1))
    jacobian = point_to_line_jacobian(anchors, np.zeros(2), normals)
    residuals = np.full(50, 0.1)
    step = gauss_newton_step(
        jacobian, residuals, np.ones(50), np.array([1e-2, 1e-2, 1e-2]), np.array([0.3, 0.0, 0.0])
    )
    assert step[1] == pytest.approx(-0.1, abs=1e-3)  # the data move y onto the wall
    assert step[0] == pytest.approx(0.3, abs=1e-6)  # the prior alone sets x


def test_degenerate_direction_is_left_to_the_prior():
    # A wall whose noisy normals tilt +-0.05 rad: the data "see" x only through that noise and
    # would pull x to -0.2 m; with min_information the prior's +0.3 m decides x.
    anchors = np.column_stack([np.linspace(-3, 3, 50), np.ones(50)])
    sign = np.where(np.arange(50) % 2, 1.0, -1.0)
    normals = np.column_stack([0.05 * sign, np.ones(50)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    jacobian = point_to_line_jacobian(anchors, np.zeros(2), normals)
    prior = (np.full(3, 1e-2), np.array([0.3, 0.0, 0.0]))
    free = gauss_newton_step(jacobian, 0.01 * sign, np.ones(50), *prior)
    guarded = gauss_newton_step(jacobian, 0.01 * sign, np.ones(50), *prior, min_information=2.0)
    assert free[0] < 0.0
    assert guarded[0] == pytest.approx(0.3, abs=1e-4)
    assert abs(guarded[1]) < 1e-6


def test_a_match_carries_its_pairs_information_at_the_pose_it_found():
    # The compiled loop and the Python steps return the inlier pairs' J^T W J at the final
    # pose: what normal_equations gives there, symmetric, and large across the walls seen.
    rng = np.random.default_rng(3)
    reference = PointToLineReference.with_estimated_normals(
        points_at(np.zeros(3), noise=0.01, rng=rng), 9)
    query = points_at(np.array([0.1, -0.05, 0.03]), noise=0.01, rng=rng)
    params = ICPParams()
    for compiled in (True, False):
        result = register(reference, query, np.zeros(3), params, compiled=compiled)
        expected = reference.normal_equations(query, result.pose, params.inlier_distance,
                                              params.loss, params.loss_scale)[0]
        np.testing.assert_allclose(result.information, expected, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(result.information, result.information.T, atol=1e-9)
        assert np.linalg.eigvalsh(result.information[:2, :2])[0] > 10.0


@pytest.mark.parametrize("offset", [(0.2, -0.1, np.radians(6.0)), (-0.3, 0.15, np.radians(-10.0))])
def test_match_scans_recovers_the_pose_between_two_views(offset):
    rng = np.random.default_rng(7)
    first = np.array([-2.0, 0.5, 0.3])
    second = compose(first, offset)
    reference = points_at(first, noise=0.01, rng=rng)
    query = points_at(second, noise=0.01, rng=rng)
    result = match_scans(reference, query)
    error = relative(np.asarray(offset), result.pose)
    assert np.hypot(error[0], error[1]) < 0.01
    assert abs(error[2]) < np.radians(0.2)
    assert result.quality > 0.8  # some walls are seen from one view only
    assert result.converged


def test_a_denoised_reference_cuts_the_registration_error_of_a_noisy_map():
    # A local map like lidar_odometry's: five noisy (1 cm) scans from nearby poses merged and
    # thinned to 5 cm voxels; a sixth noisy scan is registered onto it. Lines through the
    # raw map points add the map's noise to every pair; through the denoised points, a
    # fraction of it.
    params = ICPParams(max_correspondence_distance=0.5)
    errors = {False: [], True: []}
    for seed in range(12):
        rng = np.random.default_rng(seed)
        poses = [np.array([0.2 * k, 0.1 * k, 0.05 * k]) for k in range(5)]
        merged = np.concatenate(
            [transform_points(p, points_at(p, noise=0.01, rng=rng)) for p in poses]
        )
        thinned = voxel_downsample(merged, 0.05)
        truth = np.array([0.5, 0.3, 0.15])
        query = points_at(truth, noise=0.01, rng=rng)
        for denoise in errors:
            reference = PointToLineReference.with_estimated_normals(thinned, 9, denoise)
            found = register(reference, query, compose(truth, [0.05, -0.03, 0.02]), params).pose
            error = relative(truth, found)
            errors[denoise].append(np.hypot(error[0], error[1]))
    assert np.mean(errors[True]) < 0.7 * np.mean(errors[False])


def test_pairs_anchor_on_the_given_anchors_along_the_stored_normals():
    points = np.column_stack([np.linspace(0.0, 1.0, 11), np.zeros(11)])
    anchors = points + [0.0, 0.01]  # the wall's denoised position, 1 cm above the readings
    normals = np.tile([0.0, 1.0], (11, 1))
    reference = PointToLineReference(points, normals, anchors=anchors)
    pairs = reference.correspond(np.array([[0.31, 0.2], [0.69, -0.1]]), max_distance=0.5)
    np.testing.assert_array_equal(pairs.anchors, anchors[[3, 7]])
    np.testing.assert_array_equal(pairs.normals, normals[[3, 7]])


def test_compiled_and_python_registrations_assess_the_same_inliers():
    """The compiled loop's quality and RMSE come from the same inliers as the Python steps'."""
    rng = np.random.default_rng(3)
    reference = PointToLineReference.with_estimated_normals(
        points_at(np.array([-2.0, 0.5, 0.3]), noise=0.01, rng=rng), 9, True)
    query = points_at(np.array([-1.9, 0.55, 0.35]), noise=0.01, rng=rng)
    guess = np.array([0.05, 0.0, 0.0])
    compiled = register(reference, query, guess, ICPParams())
    stepped = register(reference, query, guess, ICPParams(), compiled=False)
    assert 0.5 < compiled.quality == stepped.quality
    assert compiled.rmse == pytest.approx(stepped.rmse, rel=1e-9)


def test_normals_set_after_a_registration_are_the_ones_paired_on():
    """Normals, flags and anchors assigned to a reference after it was matched against are
    what the next match pairs on (as on a reference built with them)."""
    points = points_at(np.array([-2.0, 0.5, 0.3]))
    query = points_at(np.array([-1.9, 0.55, 0.35]))
    fitted = PointToLineReference.with_estimated_normals(points, 9, True)
    reference = PointToLineReference(points)
    register(reference, query, np.zeros(3))
    reference.normals, reference.valid_normals, reference.anchors = (
        fitted.normals, fitted.valid_normals, fitted.anchors)
    again = register(reference, query, np.zeros(3))
    expected = register(PointToLineReference(points, fitted.normals, fitted.valid_normals,
                                             fitted.anchors), query, np.zeros(3))
    np.testing.assert_array_equal(again.pose, expected.pose)
    assert again.rmse == expected.rmse


def test_quality_drops_without_overlap():
    reference = points_at(np.array([-2.0, 0.5, 0.3]))
    unrelated = np.column_stack([np.linspace(20, 25, 100), np.linspace(-5, 5, 100)])
    assert match_scans(reference, unrelated).quality < 0.1


def test_a_noisy_corridors_axis_is_left_to_the_prior():
    # Two walls 3 m apart seen with 3 cm noise, a map of five scans' worth thinned to 5 cm;
    # nothing fixes the motion along them, so the registration must keep the prior's 0.1 m
    # there. Fitted through 9 neighbours, the map's normals fail the line test and its pairs
    # fall back to two-nearest-point lines pointing anywhere in the walls' band, whose noise
    # passes for information along the axis; grown neighbourhoods keep the walls lines.
    params = ICPParams(max_correspondence_distance=0.5, min_information=2.0)
    prior = np.array([0.1, 0.0, 0.0])
    information = np.array([(0.02 / 0.03) ** 2, (0.02 / 0.03) ** 2, (0.02 / 0.1) ** 2])

    def corridor(rng: np.random.Generator, n_points: int) -> np.ndarray:
        x = rng.uniform(-4.0, 4.0, n_points)
        return np.column_stack([x, rng.choice([-1.5, 1.5], n_points)
                                + 0.03 * rng.standard_normal(n_points)])

    errors: dict[int | None, list[float]] = {None: [], 72: []}
    for seed in range(6):
        rng = np.random.default_rng(seed)
        thinned = voxel_downsample(corridor(rng, 2000), 0.05)
        query = corridor(rng, 400)
        for max_k in errors:
            reference = PointToLineReference.with_estimated_normals(thinned, 9, True, max_k)
            pose = register(reference, query, prior, params, prior, information).pose
            errors[max_k].append(abs(pose[0] - prior[0]))
    assert np.median(errors[72]) < 1e-3
    assert np.median(errors[None]) > 0.01


def test_icp_estimator_follows_a_ray_cast_drive():
    rng = np.random.default_rng(11)
    setup = SensorSetup(np.zeros((1, 3)), ANGLES, 20.0)
    estimator = make("icp")
    truth = [np.array([-3.0, -2.0, 0.6])]
    estimator.reset(setup, truth[0])
    step = np.array([0.08, 0.0, 0.03])  # 0.8 m/s, 0.3 rad/s at 10 Hz
    for k in range(40):
        if k:
            truth.append(compose(truth[-1], step))
        estimator.update({"lidar_1": ray_cast(truth[-1], noise=0.01, rng=rng)}, 0.1 * k)
    end_error = relative(truth[-1], estimator.pose)
    travelled = 39 * 0.08
    assert np.hypot(end_error[0], end_error[1]) < 0.01 * travelled
    assert abs(wrap_angle(end_error[2])) < np.radians(0.5)
    assert estimator.trajectory.shape == (40, 3)



def test_icp_estimator_finds_the_car_after_scans_lost_in_a_turn():
    # 15 scans (1.5 s) lost while the car turned 70 degrees against the turn it held: neither
    # the one-interval nor the whole-gap guess is within ICP's reach, the search on the last
    # scan is
    rng = np.random.default_rng(3)
    estimator = make("icp")
    pose = np.array([-3.0, -2.0, 0.6])
    estimator.reset(SensorSetup(np.zeros((1, 3)), ANGLES, 20.0), pose)
    step, t = np.array([0.08, 0.0, 0.03]), 0.0
    for k in range(30):
        if k == 20:
            pose, t = compose(pose, [0.3, 0.0, np.radians(-70.0)]), t + 1.5
        estimator.update({"lidar_1": ray_cast(pose, noise=0.01, rng=rng)}, t)
        pose, t = compose(pose, step), t + 0.1
    error = relative(compose(pose, inverse(step)), estimator.pose)
    assert np.hypot(error[0], error[1]) < 0.05 and abs(wrap_angle(error[2])) < np.radians(1.0)
    assert estimator.health.clock_jumps == 1


def test_icp_estimator_starts_each_match_from_the_last_increment(monkeypatch):
    import estimators.matching.icp_estimator as icp

    guesses, results = [], []

    def spy(reference, query, initial_guess, params, prior_pose, prior_information):
        guesses.append(np.array(initial_guess, dtype=float))
        results.append(real_register(reference, query, initial_guess, params, prior_pose,
                                     prior_information).pose)
        return MatchResult(results[-1], 1.0, 0.0, 1, True)

    real_register = icp.register
    monkeypatch.setattr(icp, "register", spy)
    estimator = make("icp")
    pose = np.array([-3.0, -2.0, 0.6])
    estimator.reset(SensorSetup(np.zeros((1, 3)), ANGLES, 20.0), pose)
    for k in range(4):
        estimator.update({"lidar_1": ray_cast(pose)}, 0.1 * k)
        pose = compose(pose, np.array([0.08, 0.0, 0.03]))
    np.testing.assert_array_equal(guesses[0], np.zeros(3))
    for guess, previous in zip(guesses[1:], results[:-1], strict=True):
        np.testing.assert_array_equal(guess, previous)
    np.testing.assert_allclose(results[-1], [0.08, 0.0, 0.03], atol=1e-3)

def test_bad_input_is_named():
    with pytest.raises(ValueError, match="unknown loss 'l1': expected one of cauchy, huber"):
        ICPParams(loss="l1")
    with pytest.raises(ValueError, match="trim_ratio: expected a share"):
        ICPParams(trim_ratio=0.0)
    with pytest.raises(ValueError, match="max_correspondence_distance: expected a positive"):
        ICPParams(max_correspondence_distance=-1.0)
    with pytest.raises(ValueError, match=r"reference points: expected shape \(N >= 2, 2\)"):
        PointToLineReference(np.zeros((5, 3)))
    with pytest.raises(ValueError, match=r"anchors: expected the points' shape \(5, 2\)"):
        PointToLineReference(np.arange(10.0).reshape(5, 2), anchors=np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"query points: expected shape \(M, 2\)"):
        match_scans(np.zeros((5, 2)) + np.arange(5)[:, None], np.zeros(4))
    with pytest.raises(ValueError, match="initial_guess: expected a pose"):
        match_scans(np.arange(10.0).reshape(5, 2), np.arange(10.0).reshape(5, 2), (0.0, 0.0))
    with pytest.raises(ValueError, match="unknown loss"):
        robust_weights(np.zeros(3), "tukey", 1.0)


@pytest.mark.parametrize(("settings", "message"), [
    ({"noise_sigma": 0.0}, "noise_sigma: expected a positive value"),
    ({"prior_sigma_translation": -0.1}, "prior_sigma_translation: expected a positive"),
    ({"prior_sigma_rotation": float("nan")}, "prior_sigma_rotation: expected a positive"),
    ({"normal_neighbours": 2}, "normal_neighbours: expected an integer >= 3"),
    ({"normal_neighbours": 9.5}, "normal_neighbours: expected an integer >= 3"),
    ({"max_normal_neighbours": 5}, r"max_normal_neighbours: expected an integer >= 9"),
    ({"min_information": -1.0}, "min_information: expected a number of points >= 0"),
    ({"min_information": float("nan")}, "min_information: expected a number of points >= 0"),
])
def test_icp_settings_out_of_range_are_named_config_errors(settings: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        make("icp", **settings)
