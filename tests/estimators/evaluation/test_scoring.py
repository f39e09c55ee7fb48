"""``ScoreEstimator``: per-episode metrics of an estimator running online on ``DualLidar-v0``."""

from __future__ import annotations

from functools import partial

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from estimators.evaluation.metrics import evaluate
from estimators.evaluation.scoring import ScoreEstimator
from estimators.paper.pc import ZeroMotion

SHORT = {"max_episode_time": 1.5}  # 15 steps, then truncation
FORWARD = np.array([0.6, 0.0], dtype=np.float32)


def _episode(env: gym.Env, seed: int = 0) -> tuple[list[dict], dict]:
    """Drive forward until the episode ends; return all infos and the last one."""
    _, info = env.reset(seed=seed)
    infos = [info]
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(FORWARD)
        infos.append(info)
        done = terminated or truncated
    return infos, info


def test_episode_end_reports_the_metrics_of_the_online_estimate() -> None:
    env = ScoreEstimator(gym.make("DualLidar-v0", world="open_cylinders", config=SHORT), "pc")
    infos, last = _episode(env)
    assert all("estimator" not in info for info in infos[:-1])
    report = last["estimator"]
    truth = np.array([info["pose"] for info in infos])
    np.testing.assert_allclose(env.true_trajectory, truth)
    assert env.estimated_trajectory.shape == truth.shape
    expected = evaluate(env.estimated_trajectory, truth)
    assert report["ate_rmse_m"] == pytest.approx(expected.ate_rmse_m)
    assert report["accuracy_percent"] == pytest.approx(expected.accuracy_percent)
    assert report["n_poses"] == len(truth) and report["steps"] == len(truth) - 1
    assert report["ms_per_step"] > 0.0
    # the estimate starts at the true start and moves roughly as the car did
    np.testing.assert_allclose(env.estimated_trajectory[0], truth[0])
    assert report["drift_percent"] < 50.0


def test_zero_estimator_ate_is_the_distance_from_the_start() -> None:
    env = ScoreEstimator(gym.make("DualLidar-v0", config=SHORT), ZeroMotion())
    infos, last = _episode(env)
    positions = np.array([info["pose"][:2] for info in infos])
    distances = np.linalg.norm(positions - positions[0], axis=1)
    assert last["estimator"]["ate_rmse_m"] == pytest.approx(np.sqrt(np.mean(distances**2)))
    assert last["estimator"]["accuracy_percent"] == pytest.approx(0.0)


def test_a_second_episode_starts_afresh() -> None:
    env = ScoreEstimator(gym.make("DualLidar-v0", config=SHORT), "zero")
    _, first = _episode(env, seed=1)
    _, second = _episode(env, seed=1)
    reports = [dict(info["estimator"]) for info in (first, second)]
    for report in reports:
        del report["ms_per_step"]
    assert reports[0] == reports[1]
    assert len(env.true_trajectory) == first["estimator"]["n_poses"]


def test_works_under_make_vec() -> None:
    envs = gym.make_vec(
        "DualLidar-v0",
        num_envs=2,
        vectorization_mode="sync",
        wrappers=[partial(ScoreEstimator, estimator="zero")],
        config=SHORT,
    )
    envs.reset(seed=0)
    actions = np.repeat(FORWARD[None], 2, axis=0)
    for _ in range(40):
        _, _, terminated, truncated, infos = envs.step(actions)
        if np.any(terminated | truncated):
            break
    assert "estimator" in infos and infos["_estimator"].any()
    ended = infos["_estimator"]
    assert np.all(infos["estimator"]["ate_rmse_m"][ended] > 0.0)
    envs.close()


def test_bad_arguments_are_readable_errors() -> None:
    env = gym.make("DualLidar-v0", config=SHORT)
    with pytest.raises(KeyError, match="unknown estimator 'nope'"):
        ScoreEstimator(env, "nope")
    with pytest.raises(TypeError, match="expected an Estimator or a registered name"):
        ScoreEstimator(env, 3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown align 'x': expected one of none, se2"):
        ScoreEstimator(env, "zero", align="x")
