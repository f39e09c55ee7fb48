"""The training script never replaces a model by accident, and shows progress."""

from __future__ import annotations

from pathlib import Path

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
