"""The agents' command lines (``duallidar drive/train/imitate``, ``python -m agents.*``): a bad
value is a one-line error naming the option, exit status 2, before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

from agents import evaluate

BAD_EVALUATE = [
    (["--worlds", "hallwy"], "--worlds: unknown name 'hallwy'"),
    (["--traces", "zig"], "--traces: unknown name 'zig'"),
    (["--pose-sources", "gps"], "--pose-sources: unknown name 'gps'"),
    (["--episodes", "0"], "argument --episodes: expected an integer >= 1, got 0"),
    (["--episodes", "-2"], "argument --episodes"),
    (["--base-seed", "-1"], "argument --base-seed: expected a seed"),
    (["--base-seed", str(2**32 - 1), "--episodes", "2"], "--base-seed: expected base seed"),
    (["--moving-obstacles", "-1"], "argument --moving-obstacles"),
    (["--drivers", "robot"], "argument --drivers: invalid choice"),
    (["--sb3-model", "nowhere.zip"], "--sb3-model: no such file nowhere.zip"),
    (["--pose-params", "{"], "argument --pose-params"),
]


def exit_of(main, argv: list[str], capsys: pytest.CaptureFixture[str], **kw) -> tuple[int, str]:
    with pytest.raises(SystemExit) as stop:
        main(argv, **kw)
    return int(stop.value.code), capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), BAD_EVALUATE)
def test_evaluate_refuses_bad_values(argv: list[str], message: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, err = exit_of(evaluate.main, argv, capsys)
    assert code == 2
    assert message in err
    assert err.startswith("usage: python -m agents.evaluate")
    assert "Traceback" not in err


def test_evaluate_names_itself_as_drive_under_duallidar(
        capsys: pytest.CaptureFixture[str]) -> None:
    code, err = exit_of(evaluate.main, ["--episodes", "0"], capsys, prog="duallidar drive")
    assert code == 2 and err.startswith("usage: duallidar drive")


@pytest.mark.parametrize(("module", "argv", "message"), [
    ("train", ["--timesteps", "0"], "argument --timesteps: expected an integer >= 1, got 0"),
    ("train", ["--timesteps", "-5"], "argument --timesteps"),
    ("train", ["--n-envs", "0"], "argument --n-envs"),
    ("train", ["--seed", "-1"], "argument --seed"),
    ("imitate", ["--iterations", "0"], "argument --iterations"),
    ("imitate", ["--steps", "-1"], "argument --steps"),
    ("imitate", ["--net-arch", "64", "0"], "argument --net-arch"),
    ("imitate", ["--expert", "lazy"], "argument --expert: invalid choice"),
])
def test_training_refuses_bad_counts(module: str, argv: list[str], message: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("yaml")
    main = __import__(f"agents.{module}", fromlist=["main"]).main
    code, err = exit_of(main, argv, capsys)
    assert code == 2 and message in err
    assert err.startswith(f"usage: python -m agents.{module}")


@pytest.mark.parametrize(("text", "message"), [
    ("DualLidar-v0: [unclosed", "not valid YAML"),
    ("- a list\n", "'DualLidar-v0' entry"),
    ("DualLidar-v0:\n  n_envs: 2\n", "to hold 'n_timesteps'"),
])
def test_train_names_a_malformed_hyperparameters_file(
        tmp_path: Path, text: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("yaml")
    from agents import train

    path = tmp_path / "hyper.yaml"
    path.write_text(text)
    code, err = exit_of(train.main, ["--hyperparameters", str(path), "--out",
                                     str(tmp_path / "m.zip")], capsys)
    assert code == 2
    assert "--hyperparameters:" in err and message in err


def test_train_refuses_an_existing_out_without_overwrite(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("yaml")
    from agents import train

    (tmp_path / "m.zip").write_bytes(b"")
    code, err = exit_of(train.main, ["--out", str(tmp_path / "m.zip")], capsys)
    assert code == 2 and "--out:" in err and "--overwrite" in err
