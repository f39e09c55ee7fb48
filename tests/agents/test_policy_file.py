"""Model zips are read weights-only: a crafted zip whose pickles would run code loads without
running it, gives the same actions as ``PPO.load`` for the shipped model, and what cannot be
read without unpickling is refused unless ``trust_model`` is given."""

from __future__ import annotations

import base64
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lidar_env.core.errors import ConfigError

pytest.importorskip("stable_baselines3", reason="the agents extra is not installed")

from agents.policy_file import load_policy  # noqa: E402
from agents.sb3_driver import SHIPPED_MODEL, SB3Driver  # noqa: E402


class WritesAFile:
    """Unpickling this runs ``open(marker, "w").write(...)``."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (exec, (f"with open({str(self.marker)!r}, 'w') as f: f.write('ran')",))


def rewrite(source: Path, target: Path, change) -> Path:
    """A copy of the zip ``source`` whose ``data`` JSON is ``change(data)``."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for item in old.infolist():
            payload = old.read(item)
            if item.filename == "data":
                payload = json.dumps(change(json.loads(payload))).encode()
            new.writestr(item, payload)
    return target


def crafted(tmp_path: Path, marker: Path) -> Path:
    evil = base64.b64encode(pickle.dumps(WritesAFile(marker))).decode()

    def change(data):
        for key in ("observation_space", "action_space", "policy_class", "lr_schedule"):
            data[key][":serialized:"] = evil
        return data

    return rewrite(SHIPPED_MODEL, tmp_path / "crafted.zip", change)


def test_a_crafted_zip_runs_no_code(tmp_path) -> None:
    marker = tmp_path / "ran.txt"
    path = crafted(tmp_path, marker)
    driver = SB3Driver(path)
    assert driver.model.observation_space.shape == (86,)
    assert not marker.exists()
    try:  # PPO.load runs the payload: this is what trust_model allows
        load_policy(path, trust_model=True)
    except Exception:  # noqa: BLE001, S110 - the payload replaced the spaces: loading fails later
        pass
    assert marker.read_text() == "ran"


def test_the_shipped_model_acts_as_ppo_load_makes_it_act() -> None:
    from stable_baselines3 import PPO

    observations = np.random.default_rng(0).uniform(-1, 1, (100, 86)).astype(np.float32)
    expected, _ = PPO.load(SHIPPED_MODEL, device="cpu").predict(observations, deterministic=True)
    actions, _ = load_policy(SHIPPED_MODEL).predict(observations, deterministic=True)
    np.testing.assert_array_equal(actions, expected)


def test_what_needs_unpickling_or_is_not_a_model_is_refused(tmp_path) -> None:
    def pickled_kwargs(data):
        data["policy_kwargs"] = {":type:": "<class 'dict'>", ":serialized:": "gAR9lC4="}
        return data

    def custom_activation(data):
        data["policy_kwargs"]["activation_fn"] = "ReLU"
        return data

    for change, message in ((pickled_kwargs, "policy_kwargs are pickled"),
                            (custom_activation, r"policy_kwargs \['activation_fn'\] need")):
        path = rewrite(SHIPPED_MODEL, tmp_path / "m.zip", change)
        with pytest.raises(ConfigError, match=f"{message}.*trust_model=True"):
            load_policy(path)
    (tmp_path / "not.zip").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(ConfigError, match="not.zip: expected a Stable-Baselines3 PPO zip"):
        load_policy(tmp_path / "not.zip")
    with zipfile.ZipFile(tmp_path / "empty.zip", "w") as archive:
        archive.writestr("data", "{}")
    with pytest.raises(ConfigError, match="with 'policy.pth'"):
        load_policy(tmp_path / "empty.zip")
