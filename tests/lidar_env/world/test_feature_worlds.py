"""The feature-density world family: density 0 is today's world, features come from the seed,
grow with the density, keep every trace seed drivable, and bad options are named errors."""

import hashlib

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from lidar_env.core.errors import ConfigError
from lidar_env.routes.traces import TRACE_NAMES
from lidar_env.world.built_in import (
    LAYOUT_CLEARANCE,
    PAPER_TRACES,
    built_in_layout,
    check_world_name,
    make_scene,
)
from lidar_env.world.feature_worlds import (
    FEATURE_KINDS,
    FEATURE_WORLDS,
    MAX_FEATURE_DENSITY,
    feature_world_name,
)

#: sha256 of (circles, walls, polygons, bounds, name) of the worlds before the family existed
#: (computed from lidar_env/world/built_in.py at commit 40464b3).
TODAY = {
    "hallway": "ac613c9dec972dd44ff878e31743fc8a07280880db23c0d5317da29d82e8fef9",
    "closed_to_open": "d17e8f3977e0053fa3bad1f603a19454a11b5eb40175e3034a8a6ca983b9d2cd",
}


def _fingerprint(world, with_name: bool = True) -> str:
    digest = hashlib.sha256()
    for array in (world.circles, world.walls, *world.polygons, np.array(world.bounds)):
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    if with_name:
        digest.update(world.name.encode())
    return digest.hexdigest()


def _fresh(name):
    built_in_layout.cache_clear()
    return built_in_layout(name)


@pytest.mark.parametrize("base", FEATURE_WORLDS)
@pytest.mark.parametrize("options", ["", "?feature_density=0", "?feature_density=0&feature_seed=7"])
def test_density_zero_is_todays_world_bit_for_bit(base, options):
    layout = _fresh(base + options)
    assert _fingerprint(layout.world) == TODAY[base]
    assert layout.features == ()
    assert check_world_name(base + options) == base


@pytest.mark.parametrize("base", FEATURE_WORLDS)
def test_density_zero_episode_is_todays_episode(base):
    def rollout(world):
        env = gym.make("DualLidar-v0", world=world)
        obs, _ = env.reset(seed=3)
        scans = [obs["lidar_1"].copy()]
        for _ in range(5):
            obs, *_ = env.step(np.array([1.0, 0.2], dtype=np.float32))
            scans.append(obs["lidar_1"].copy())
        return np.array(scans)

    np.testing.assert_array_equal(rollout(base), rollout(f"{base}?feature_density=0"))


@pytest.mark.parametrize("base", FEATURE_WORLDS)
def test_features_come_from_the_seed(base):
    first = _fresh(feature_world_name(base, 4.0, seed=1)).world
    again = _fresh(feature_world_name(base, 4.0, seed=1)).world
    other = _fresh(feature_world_name(base, 4.0, seed=2)).world
    assert _fingerprint(first) == _fingerprint(again)
    assert _fingerprint(first, with_name=False) != _fingerprint(other, with_name=False)


@pytest.mark.parametrize("base", FEATURE_WORLDS)
def test_density_grows_the_feature_count_and_keeps_the_sparser_features(base):
    today = built_in_layout(base).world
    perimeter = float(np.sum(np.hypot(*(today.walls[:, 2:] - today.walls[:, :2]).T)))
    layouts = [built_in_layout(feature_world_name(base, d)) for d in (1.0, 2.0, 4.0, 8.0)]
    counts = [len(layout.features) for layout in layouts]
    assert counts == [round(d * perimeter / 10.0) for d in (1.0, 2.0, 4.0, 8.0)]
    for sparse, dense in zip(layouts[:-1], layouts[1:], strict=True):
        assert dense.features[: len(sparse.features)] == sparse.features
        assert len(dense.world.segments) >= len(sparse.world.segments)
    assert set(layouts[-1].features) == set(FEATURE_KINDS)
    extra = layouts[-1].world
    assert len(extra.circles) + len(extra.polygons) > len(today.circles) + len(today.polygons)


@pytest.mark.parametrize("base", FEATURE_WORLDS)
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("trace", TRACE_NAMES)
def test_every_trace_seed_fits_at_full_size_at_the_highest_density(base, seed, trace):
    name = feature_world_name(base, MAX_FEATURE_DENSITY, seed)
    layout = built_in_layout(name)
    scene = make_scene(name, trace)
    assert scene.trace.length == pytest.approx(layout.lengths[trace], abs=1e-2)
    assert np.min(scene.world.clearance(scene.trace.waypoints)) >= LAYOUT_CLEARANCE
    assert PAPER_TRACES[name] == PAPER_TRACES[base]


def test_the_env_drives_a_feature_world_given_by_name_or_reset_option():
    name = "hallway?feature_density=4&feature_seed=2"
    env = gym.make("DualLidar-v0", world=name)
    env.reset(seed=0)
    assert env.unwrapped.world is built_in_layout(name).world
    env.reset(seed=0, options={"world": "closed_to_open?feature_density=2"})
    assert env.unwrapped.world.name == "closed_to_open?feature_density=2&feature_seed=0"


@pytest.mark.parametrize("bad, named", [
    ("hallway?feature_density=-1", "feature_density"),
    ("hallway?feature_density=nan", "feature_density"),
    ("hallway?feature_density=inf", "feature_density"),
    ("hallway?feature_density=1e9", "feature_density"),
    ("hallway?feature_density=many", "feature_density"),
    ("hallway?feature_seed=-3", "feature_seed"),
    ("hallway?density=1", "density=1"),
    ("hallway?feature_density=1&feature_density=2", "each once"),
    ("open_cylinders?feature_density=1", "open_cylinders"),
])
def test_bad_options_are_a_named_config_error(bad, named):
    with pytest.raises(ConfigError, match=named):
        check_world_name(bad)
    with pytest.raises(ConfigError, match=named):
        gym.make("DualLidar-v0", world=bad)


@pytest.mark.parametrize("density", [-0.5, float("nan"), MAX_FEATURE_DENSITY * 2])
def test_feature_world_name_rejects_bad_densities(density):
    with pytest.raises(ConfigError, match="feature_density"):
        feature_world_name("hallway", density)
