"""ROS bags: a simulated drive written and read back is the same drive, in all three formats;
bad bags give readable :class:`LogFormatError` naming the file and topic."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from estimators.base import SensorSetup, default_beam_angles  # noqa: E402
from estimators.datasets import Recording, load_bag, run_on_log, write_bag  # noqa: E402
from estimators.datasets.rosbag_reader import clock_seconds  # noqa: E402
from estimators.datasets.rosbag_writer import (  # noqa: E402
    TRUTH_TOPIC,
    BagSink,
    header,
    laser_scan,
    nanoseconds,
)
from estimators.evaluation.nav_path import read_path_bag, write_path_bag  # noqa: E402
from estimators.leaderboard.recording import record, replay  # noqa: E402
from estimators.leaderboard.records import Scenario  # noqa: E402
from estimators.registry import make  # noqa: E402
from lidar_env.core.errors import LogFormatError  # noqa: E402
from lidar_env.core.se2 import compose  # noqa: E402

BAG_NAMES = {"sqlite3": "drive", "mcap": "drive", "ros1": "drive.bag"}


@pytest.fixture(scope="module")
def drive():
    """A short zigzag drive with the default two Lidars and 1 cm noise."""
    return record(Scenario("hallway", "zigzag", 3, config={"max_episode_time": 12.0}))


def ros_clock(times: np.ndarray) -> np.ndarray:
    """Times as a bag stores them (integer ns) and reads them back [s]."""
    return np.array([clock_seconds(*divmod(nanoseconds(t), 10**9)) for t in times])


@pytest.mark.parametrize("storage", sorted(BAG_NAMES))
def test_a_drive_read_back_is_the_same_drive(drive, tmp_path: Path, storage: str) -> None:
    path = write_bag(tmp_path / BAG_NAMES[storage], drive.setup, drive.times, drive.scans,
                     drive.poses, storage=storage)
    target = path if storage == "ros1" else next(f for f in path.iterdir()
                                                 if f.suffix in (".db3", ".mcap"))
    for source in {path, target}:
        recording = load_bag(source, truth_topic=TRUTH_TOPIC)
        assert recording.topics == ("/lidar_1/scan", "/lidar_2/scan")
        assert recording.frames == ("lidar_1", "lidar_2")
        np.testing.assert_array_equal(recording.setup.mounts, drive.setup.mounts)
        np.testing.assert_array_equal(recording.setup.beam_angles, drive.setup.beam_angles)
        assert recording.setup.max_range == drive.setup.max_range
        for key in drive.setup.keys:
            np.testing.assert_array_equal(recording.scans[key], drive.scans[key])
        assert np.max(np.abs(recording.times - drive.times)) < 1e-9
        np.testing.assert_array_equal(recording.truth, drive.poses)
        assert recording.dropped == 0


@pytest.mark.parametrize("estimator", ["lidar_odometry", "pc_fusion"])
def test_an_estimator_on_the_bag_gives_the_direct_run_trajectory(drive, tmp_path, estimator):
    recording = load_bag(write_bag(tmp_path / "drive", drive.setup, drive.times, drive.scans))
    # The bag's clock is integer nanoseconds: the direct run sees the same clock.
    direct = replay(dataclasses.replace(drive, times=ros_clock(drive.times)), estimator)
    model = make(estimator)
    model.reset(recording.setup, drive.poses[0])
    for observation, t in zip(recording.observations(), recording.times, strict=True):
        model.update(observation, float(t))
    np.testing.assert_array_equal(model.trajectory, direct.poses)
    run = run_on_log(make(estimator), recording)
    assert run.poses.shape == (len(drive), 3)
    np.testing.assert_allclose(run.poses[0], 0.0)


def test_lidars_on_their_own_clocks_are_paired_by_stamp(drive, tmp_path) -> None:
    """lidar_2 fires 30 ms after lidar_1 and misses one sweep: each lidar_1 scan pairs with
    the lidar_2 scan of its own sweep, and the scan without a partner is dropped."""
    setup = SensorSetup(drive.setup.mounts[1:], drive.setup.beam_angles, drive.setup.max_range)
    lidar_2 = tmp_path / "second"
    keep = np.r_[0:5, 6:len(drive)]
    write_bag(lidar_2, setup, drive.times[keep] + 0.03, {"lidar_1": drive.scans["lidar_2"][keep]})
    first_setup = SensorSetup(drive.setup.mounts[:1], setup.beam_angles, 10.0)
    first = write_bag(tmp_path / "first", first_setup, drive.times,
                      {"lidar_1": drive.scans["lidar_1"]})
    merged = merge_bags(tmp_path / "merged", [(first, "/lidar_1/scan", "/front"),
                                               (lidar_2, "/lidar_1/scan", "/rear")])
    recording = load_bag(merged, mounts=drive.setup.mounts)
    assert recording.topics == ("/front", "/rear")
    assert recording.dropped == 1 and len(recording) == len(drive) - 1
    np.testing.assert_array_equal(recording.scans["lidar_2"], drive.scans["lidar_2"][keep])
    np.testing.assert_array_equal(recording.scans["lidar_1"], drive.scans["lidar_1"][keep])


def merge_bags(path: Path, parts: list[tuple[Path, str, str]]) -> Path:
    """Copy LaserScan topics of several bags, renamed, into one ROS 2 bag (no tf)."""
    from rosbags.highlevel import AnyReader

    with BagSink(path, "sqlite3") as sink:
        for source, topic, new_topic in parts:
            with AnyReader([source]) as reader:
                connections = [c for c in reader.connections if c.topic == topic]
                for connection, stamp, raw in reader.messages(connections=connections):
                    message = reader.deserialize(raw, connection.msgtype)
                    sink.write(new_topic, message, stamp * 1e-9)
    return path


def write_scans(path: Path, stamps, rows, frame: str = "laser", range_min: float = 0.0) -> Path:
    """A bag with one LaserScan topic ``/scan`` (360 beams, 10 m) and no tf; messages are
    written 0.1 s apart on the bag's clock, whatever their header ``stamps`` [s]."""
    setup = SensorSetup(np.zeros((1, 3)), default_beam_angles(360), 10.0)
    with BagSink(path, "sqlite3") as sink:
        types = sink.typestore.types
        for step, (t, ranges) in enumerate(zip(stamps, rows, strict=True)):
            message = laser_scan(types, header(types, t, frame, step, False), np.asarray(ranges),
                                 (0.0, 2 * np.pi / 360), setup.sensors[0])
            message.ranges = np.asarray(ranges, dtype=np.float32)
            message.range_min = range_min
            sink.write("/scan", message, 0.1 * step)
    return path


def test_no_return_readings_read_max_range(tmp_path) -> None:
    row = np.full(360, 3.0)
    row[:4] = [np.nan, np.inf, 12.0, 0.05]  # NaN, inf, beyond range_max, below range_min
    recording = load_bag(write_scans(tmp_path / "b", [0.0, 0.1], [row, row], range_min=0.1))
    assert isinstance(recording, Recording)
    np.testing.assert_array_equal(recording.scans["lidar_1"][:, :4], 10.0)
    np.testing.assert_array_equal(recording.scans["lidar_1"][:, 4:], 3.0)
    np.testing.assert_array_equal(recording.setup.mounts, np.zeros((1, 3)))


def test_mounts_compose_along_the_static_tf_chain(tmp_path) -> None:
    setup = SensorSetup(np.zeros((1, 3)), default_beam_angles(360), 10.0)
    plate, laser = np.array([0.3, -0.1, 0.5]), np.array([0.05, 0.02, 1.0])
    with BagSink(tmp_path / "tf.bag", "ros1") as sink:
        types = sink.typestore.types
        from estimators.datasets.rosbag_writer import _transform

        transforms = [_transform(types, header(types, 0.0, "base_link", 0, True), "plate", plate),
                      _transform(types, header(types, 0.0, "plate", 0, True), "laser", laser)]
        sink.write("/tf_static", types["tf2_msgs/msg/TFMessage"](transforms=transforms), 0.0)
        for step in range(3):
            stamp = header(types, 0.1 * step, "laser", step, True)
            scan = laser_scan(types, stamp, np.full(360, 2.0), (0.0, 2 * np.pi / 360),
                              setup.sensors[0])
            sink.write("/scan", scan, 0.1 * step)
    recording = load_bag(tmp_path / "tf.bag")
    np.testing.assert_allclose(recording.setup.mounts[0], compose(plate, laser), atol=1e-12)
    np.testing.assert_allclose(load_bag(tmp_path / "tf.bag", base_frame="plate").setup.mounts[0],
                               laser, atol=1e-12)


def test_bad_bags_name_the_file_and_the_topic(drive, tmp_path) -> None:
    bag = write_bag(tmp_path / "drive", drive.setup, drive.times, drive.scans)
    with pytest.raises(LogFormatError, match=r"/front.*expected some of /lidar_1/scan, "
                                             r"/lidar_2/scan"):
        load_bag(bag, topics=["/front"])
    path_only = write_path_bag(tmp_path / "path", drive.times, drive.poses)
    with pytest.raises(LogFormatError, match=r"path: expected at least one sensor_msgs/msg/"
                                             r"LaserScan topic, found /estimate/path"):
        load_bag(path_only)
    row = np.full(360, 2.0)
    backwards = write_scans(tmp_path / "backwards", [0.0, 0.2, 0.1], [row] * 3)
    with pytest.raises(LogFormatError, match=r"backwards, topic /scan: header stamps must "
                                             r"increase strictly; message 2"):
        load_bag(backwards)
    for name, content in (("junk.bag", b"#ROSBAG V2.0\n" + bytes(100)), ("junk.db3", b"x" * 64),
                          ("junk.mcap", b"\x89MCAP0\r\n" + bytes(20))):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(LogFormatError, match=rf"{name}: not a readable ROS bag"):
            load_bag(tmp_path / name)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_bag(tmp_path / "nowhere.bag")


def test_two_lidars_without_tf_need_mounts(drive, tmp_path) -> None:
    setup = SensorSetup(drive.setup.mounts[:1], drive.setup.beam_angles, drive.setup.max_range)
    one = write_bag(tmp_path / "one", setup, drive.times, {"lidar_1": drive.scans["lidar_1"]})
    two = merge_bags(tmp_path / "two", [(one, "/lidar_1/scan", "/a"),
                                        (one, "/lidar_1/scan", "/b")])
    with pytest.raises(LogFormatError, match=r"frames without one: lidar_1.*Pass mounts"):
        load_bag(two)
    assert load_bag(two, mounts=drive.setup.mounts).setup.n_lidars == 2


def test_a_trajectory_exports_as_nav_path(drive, tmp_path) -> None:
    poses = drive.poses.copy()
    poses[:, 2] = np.linspace(-3.1, 3.1, len(poses))
    write_path_bag(tmp_path / "path", drive.times, poses, storage="mcap")
    times, back = read_path_bag(tmp_path / "path")
    np.testing.assert_allclose(times, drive.times, atol=1e-9)
    np.testing.assert_allclose(back, poses, atol=1e-12)


@pytest.mark.parametrize("storage", sorted(BAG_NAMES))
def test_a_truncated_bag_is_a_log_format_error(drive, tmp_path, storage: str) -> None:
    path = write_bag(tmp_path / BAG_NAMES[storage], drive.setup, drive.times, drive.scans,
                     storage=storage)
    file = path if storage == "ros1" else next(f for f in path.iterdir()
                                               if f.suffix in (".db3", ".mcap"))
    cut = tmp_path / f"cut{file.suffix}"
    cut.write_bytes(file.read_bytes()[: file.stat().st_size * 2 // 3])
    with pytest.raises(LogFormatError, match=rf"cut{file.suffix}: not a readable ROS bag"):
        load_bag(cut)


def test_the_relations_metric_scores_a_bag_run(drive, tmp_path) -> None:
    """The relations metric against the bag's own ground truth: lidar_odometry's local
    relation error is centimetres (an error in pairing times or frames would be metres)."""
    from estimators.datasets.real_log import score_relations
    from estimators.evaluation.relations import relations_from_trajectory

    recording = load_bag(write_bag(tmp_path / "drive", drive.setup, drive.times, drive.scans,
                                   drive.poses), truth_topic=TRUTH_TOPIC)
    run = run_on_log(make("lidar_odometry"), recording)
    relations = relations_from_trajectory(recording.times, recording.truth, 1.0)
    summary = score_relations(run, relations)["all"]
    assert summary.count > 50
    assert summary.translation_mean < 0.02
