"""What the batched env returns belongs to the caller, as ``SyncVectorEnv``'s outputs do: new
arrays at every step and reset that later steps never overwrite, none sharing memory with the
env's state or with another output, so a user may keep them or write into them."""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.lidar_env.vector.test_identity import SHORT, assert_same, pair, wall_seeking_actions


def arrays_of(outputs: tuple[Any, ...]) -> list[np.ndarray]:
    """Every array in a step's or reset's outputs (observation and info dicts opened)."""
    found: list[np.ndarray] = []
    for output in outputs:
        values = output.values() if isinstance(output, dict) else [output]
        found.extend(value for value in values if isinstance(value, np.ndarray))
    return found


def scribble(outputs: tuple[Any, ...]) -> None:
    """Overwrite every returned array in place, as a careless user might."""
    for array in arrays_of(outputs):
        array[...] = True if array.dtype == np.bool_ else -7


def test_kept_outputs_stay_as_returned_through_later_steps_and_autoresets() -> None:
    batched, _ = pair(3, world="hallway", config=SHORT)
    kept = [batched.reset(seed=2)]
    snapshots = [[array.copy() for array in arrays_of(kept[0])]]
    rng, steer, ends = np.random.default_rng(0), np.zeros(3), 0
    for _ in range(120):
        outputs = batched.step(wall_seeking_actions(rng, steer))
        ends += int((outputs[2] | outputs[3]).sum())
        kept.append(outputs)
        snapshots.append([array.copy() for array in arrays_of(outputs)])
    assert ends >= 2  # autoresets rewrote sub-envs' state in between
    for t, (outputs, snapshot) in enumerate(zip(kept, snapshots, strict=True)):
        for array, expected in zip(arrays_of(outputs), snapshot, strict=True):
            np.testing.assert_array_equal(array, expected, err_msg=f"output of step {t}")


def test_outputs_share_no_memory_and_writing_into_them_changes_nothing() -> None:
    batched, reference = pair(2, world="open_cylinders", config={"moving_obstacles": 2})
    got, expected = batched.reset(seed=5), reference.reset(seed=5)
    rng, steer = np.random.default_rng(1), np.zeros(2)
    for t in range(60):
        arrays = arrays_of(got)
        for k, array in enumerate(arrays):
            assert not any(np.shares_memory(array, other) for other in arrays[k + 1:]), t
        got[-1]["_pose"][0] = False  # one key's mask is its own
        assert got[-1]["_time"][0] and got[-1]["_collision"][0]
        scribble(got)
        actions = wall_seeking_actions(rng, steer)
        got, expected = batched.step(actions), reference.step(actions)
        assert_same(got[0], expected[0], f"step {t} observation")
        assert_same(got[4], expected[4], f"step {t} info")
        for index in (1, 2, 3):
            np.testing.assert_array_equal(got[index], expected[index], f"step {t}")
