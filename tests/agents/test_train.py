"""The training script never replaces a model by accident, and shows progress."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason="the agents extra is not installed")

from agents import train  # noqa: E402
from agents.sb3_driver import SHIPPED_MODEL  # noqa: E402


def test_the_default_output_is_not_the_shipped_model() -> None:
    assert train.DEFAULT_OUT.resolve() != SHIPPED_MODEL.resolve()


def test_an_existing_model_is_refused_before_any_training(tmp_path: Path) -> None:
    out = tmp_path / "model.zip"
    out.write_bytes(b"keep me")
    with pytest.raises(train.TrainingExistsError, match="overwrite"):
        train.train(timesteps=10, out=out)
    assert out.read_bytes() == b"keep me"


def test_the_cli_names_the_existing_file(tmp_path: Path, capsys) -> None:
    out = tmp_path / "model.zip"
    out.write_bytes(b"keep me")
    with pytest.raises(SystemExit) as exit_info:
        train.main(["--out", str(out), "--timesteps", "10"])
    assert exit_info.value.code == 2
    assert str(out) in capsys.readouterr().err


@pytest.mark.slow
def test_a_short_run_writes_its_model_and_draws_a_progress_bar(tmp_path: Path, capsys) -> None:
    out = train.train(timesteps=256, n_envs=2, out=tmp_path / "m.zip", eval_episodes=1)
    assert out.is_file() and out.stat().st_size > 0
    assert "training" in capsys.readouterr().err  # the tqdm bar's label


def test_batched_training_envs_with_movers_match_the_single_ones() -> None:
    config = {"max_episode_time": 4.0, "moving_obstacles": 6}
    batched = train.make_training_vec_env(2, 3, config, {"cross_track_weight": 10.0}, "auto")
    single = train.make_training_vec_env(2, 3, config, {"cross_track_weight": 10.0}, "single")
    assert type(batched.venv).__name__ == "TraceFollowingVecEnv"  # auto batches movers too
    np.testing.assert_array_equal(batched.reset(), single.reset())
    rng, ends = np.random.default_rng(0), 0
    for t in range(100):
        actions = np.stack([rng.uniform(0.5, 1.0, 2), rng.uniform(-1.0, 1.0, 2)], 1)
        got, expected = batched.step(actions.astype(np.float32)), single.step(
            actions.astype(np.float32))
        for k, name in enumerate(("observation", "reward", "done")):
            np.testing.assert_array_equal(got[k], expected[k], err_msg=f"step {t} {name}")
        for i in range(2):
            np.testing.assert_array_equal(got[3][i]["moving_obstacles"],
                                          expected[3][i]["moving_obstacles"])
        ends += int(got[2].sum())
    assert ends >= 2
