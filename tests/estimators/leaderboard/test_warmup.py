"""The compile warm-up runs once per source: two tasks on the pool, then a marker skips it."""

from __future__ import annotations

from concurrent.futures import Future

import pytest

from estimators.leaderboard import warmup


class RecordingPool:
    """Runs nothing; records what was submitted and fails when told to."""

    def __init__(self, fail: bool = False) -> None:
        self.submitted: list[object] = []
        self.fail = fail

    def submit(self, fn, *args):
        self.submitted.append(fn)
        future: Future = Future()
        if self.fail:
            future.set_exception(RuntimeError("a kernel did not compile"))
        else:
            future.set_result(None)
        return future


@pytest.fixture
def marker(tmp_path, monkeypatch):
    path = tmp_path / "__pycache__" / "warm-abc"
    monkeypatch.setattr(warmup, "marker_path", lambda: path)
    return path


def test_a_cold_source_is_warmed_by_two_parallel_tasks_then_marked(marker) -> None:
    pool = RecordingPool()
    warmup.warm_up(pool, ("icp",))
    assert pool.submitted == [warmup.warm_env_and_mapping, warmup.warm_estimators]
    assert marker.exists()
    again = RecordingPool()
    assert warmup.warm_up(again, ("icp",)) == 0.0 and again.submitted == []


def test_a_failed_warm_up_leaves_no_marker(marker) -> None:
    warmup.warm_up(RecordingPool(fail=True), ("icp",))
    assert not marker.exists()


def test_the_marker_follows_the_source_digest() -> None:
    assert warmup.marker_path().name == f"warm-{warmup.source_digest(warmup.PROJECT_ROOT)}"


def test_the_warm_up_reaches_the_moved_on_test(monkeypatch: pytest.MonkeyPatch) -> None:
    """No static drive may reach the moving-point filter's "moved on" kernel; left to the
    workers, its compiling showed in a cold run's ms/step (lidar_odometry 4.95 against 2.2)."""
    from estimators.odometry import moving_points

    calls = []
    kernel = moving_points._near_any
    monkeypatch.setattr(moving_points, "_near_any",
                        lambda *args: calls.append(args) or kernel(*args))
    warmup._walk_away()
    assert calls and calls[0][0].shape[1] == 2


def test_the_warm_up_reaches_the_map_scoring_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernels the leaderboard's map scoring needs in variants a few steps of a plain drive
    do not reach: each compiled inside the workers' first such scenario.
    numba compiles once per argument type, so the calls are checked for those types."""
    from estimators.mapping import obstacles
    from estimators.matching import correlative
    from lidar_env.world import built_in as worlds
    from lidar_env.world import world

    calls: dict[str, list[tuple]] = {}
    for module, name in ((world, "point_queries"), (correlative, "_shifted_scores"),
                         (obstacles, "cluster_statistics"), (obstacles, "longest_arc")):
        kernel, seen = getattr(module, name), calls.setdefault(name, [])
        monkeypatch.setattr(module, name,
                            lambda *args, kernel=kernel, seen=seen: seen.append(args)
                            or kernel(*args))
    worlds.built_in_layout.cache_clear()  # built once per process: maybe by an earlier test
    warmup.warm_env_and_mapping()
    # building the closed area's world asks for the clearance of writable points
    assert any(args[0].flags.writeable for args in calls["point_queries"])
    assert calls["_shifted_scores"]
    # an arc cut out of a cluster: its bounds are columns of one array, not contiguous
    assert any(not args[1].flags.c_contiguous for args in calls["cluster_statistics"])
    assert calls["longest_arc"]
