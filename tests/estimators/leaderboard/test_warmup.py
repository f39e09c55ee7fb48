"""The compile warm-up runs once per source: announced tasks on the pool, then a marker."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import re
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


class Terminal(io.StringIO):
    """A stream that says it is a terminal, as stderr in a shell."""

    def isatty(self) -> bool:
        return True


@pytest.fixture
def dropped(monkeypatch) -> list[bool]:
    """Records the warm-up's dropping of the numba caches (never the checkout's own)."""
    calls: list[bool] = []
    monkeypatch.setattr(warmup, "drop_numba_caches", lambda: calls.append(True) or 0)
    return calls


@pytest.fixture
def marker(tmp_path, monkeypatch, dropped):
    path = tmp_path / "__pycache__" / "warm-abc"
    monkeypatch.setattr(warmup, "marker_path", lambda: path)
    return path


def test_a_cold_source_is_warmed_by_parallel_tasks_then_marked(marker, dropped) -> None:
    pool = RecordingPool()
    warmup.warm_up(pool, ("icp", "pc"), progress=False, stream=io.StringIO())
    assert pool.submitted == [warmup.warm_drive, warmup.warm_batched, warmup.warm_estimators,
                              warmup.warm_estimators, warmup.warm_mapping]
    assert marker.exists() and dropped == [True]
    again = RecordingPool()
    assert warmup.warm_up(again, ("icp",)) == 0.0 and again.submitted == []


def test_one_line_says_what_compiles_before_it_starts_and_then_how_long_it_took(
        marker) -> None:
    stream = io.StringIO()

    class Watching(RecordingPool):
        def submit(self, fn, *args):
            self.said = stream.getvalue()
            return super().submit(fn, *args)

    pool = Watching()
    warmup.warm_up(pool, ("icp",), progress=False, stream=stream)
    assert pool.said.count("\n") == 1 and "compiling the numba kernels once" in pool.said
    assert "2-core machine" in pool.said  # no compile timed here yet: the stated range
    assert warmup.last_seconds() is not None
    marker.unlink()
    stream = Terminal()
    warmup.warm_up(RecordingPool(), ("icp",), progress=True, stream=stream)
    assert "as the last time on this machine" in stream.getvalue()
    assert "\r" in stream.getvalue()  # on a terminal, the bar's frames after the line
    assert "compiling" in stream.getvalue().splitlines()[-1]


def test_a_log_that_is_not_a_terminal_gets_a_line_before_and_after_and_no_bar_frames(
        marker, monkeypatch, capsys) -> None:
    monkeypatch.setattr(warmup, "ProcessPoolExecutor",
                        lambda max_workers: contextlib.nullcontext(RecordingPool()))
    assert warmup.main() == 0 and marker.exists()
    said = capsys.readouterr().err
    assert "\r" not in said
    first, last = said.splitlines()
    assert first.startswith("compiling the numba kernels once") and "2-core machine" in first
    assert re.fullmatch(r"compiled the numba kernels in \d+ s", last)


def test_a_warm_source_says_nothing(marker, dropped) -> None:
    marker.parent.mkdir(parents=True)
    marker.touch()
    stream = io.StringIO()
    warmup.warm_up(RecordingPool(), ("icp",), stream=stream)
    assert stream.getvalue() == "" and dropped == []


def test_the_estimators_split_into_families_that_share_no_kernels() -> None:
    names = ("icp", "lidar_odometry", "pc", "pc_fusion", "slam", "zero")
    assert warmup.estimator_families(names) == [
        ("icp", "lidar_odometry", "slam", "zero"), ("pc", "pc_fusion")]
    assert warmup.estimator_families(("pc",)) == [("pc",)]
    assert [task for task, _ in warmup.tasks(())] == [
        warmup.warm_drive, warmup.warm_batched, warmup.warm_mapping]


def test_only_the_packages_numba_cache_files_are_dropped(tmp_path) -> None:
    kept = [tmp_path / "lidar_env" / "__pycache__" / "world.cpython-311.pyc",
            tmp_path / "lidar_env" / "world.nbi", tmp_path / "docs" / "__pycache__" / "a.nbi"]
    dropped = [tmp_path / "lidar_env" / "world" / "__pycache__" / "grid.cast-1.py311.nbi",
               tmp_path / "estimators" / "__pycache__" / "icp.solve-4.py311.1.nbc"]
    for path in kept + dropped:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()
    assert warmup.drop_numba_caches(tmp_path) == 2
    assert all(path.exists() for path in kept) and not any(p.exists() for p in dropped)


def test_a_failed_warm_up_leaves_no_marker(marker) -> None:
    warmup.warm_up(RecordingPool(fail=True), ("icp",))
    assert not marker.exists()


def test_the_marker_follows_the_kernel_packages_digest_which_the_set_up_computes_alike(
) -> None:
    digest = warmup.source_digest(warmup.PROJECT_ROOT, warmup.KERNEL_PACKAGES)
    assert warmup.marker_path().name == f"warm-{digest}"
    spec = importlib.util.spec_from_file_location(
        "compile_kernels", warmup.PROJECT_ROOT / "scripts" / "compile_kernels.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.source_digest() == digest


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
    warmup.warm_mapping()
    warmup.warm_batched()
    # building the closed area's world asks for the clearance of writable points
    assert any(args[0].flags.writeable for args in calls["point_queries"])
    assert calls["_shifted_scores"]
    # an arc cut out of a cluster: its bounds are columns of one array, not contiguous
    assert any(not args[1].flags.c_contiguous for args in calls["cluster_statistics"])
    assert calls["longest_arc"]
