"""Scan faults (``lidar_env.faults.scan_faults``): what each does to the ranges, and the same
seed giving the same faults."""

import numpy as np
import pytest

from lidar_env.core import ConfigError
from lidar_env.faults import (
    BeamDropout,
    Blind,
    ClockJump,
    ClockStall,
    FrozenLidar,
    RangeOutliers,
    ScanLoss,
    apply_faults,
)
from lidar_env.faults.frames import Frame

MAX = {"lidar_1": 10.0, "lidar_2": 10.0}


def frames(count=20, n=360):
    rng = np.random.default_rng(7)
    return [Frame({key: rng.uniform(1.0, 5.0, n) for key in MAX}, 0.1 * k, k)
            for k in range(count)]


def run(faults, seed=0, count=20):
    return list(apply_faults(frames(count), faults, seed, MAX))


def test_blind_every_other_scan_reads_no_return():
    out = run([Blind(every=2)])
    for frame in out:
        blind = frame.step % 2 == 1
        for scan in frame.scans.values():
            assert np.all(scan == 10.0) == blind
            assert np.any(scan == 10.0) == blind


def test_a_blind_sector_covers_its_width_and_zero_fill_reads_zero():
    out = run([Blind(every=1, offset=0, width=np.pi / 2, fill="zero", keys=("lidar_1",))])
    for frame in out:
        zeros = np.count_nonzero(frame.scans["lidar_1"] == 0.0)
        assert 89 <= zeros <= 92  # a quarter of 360 beams
        assert np.all(frame.scans["lidar_2"] > 0)


def test_blind_stretches_last_their_length():
    out = run([Blind(every=10, stretch=3, offset=2)], count=20)
    blind = [k for k, frame in enumerate(out) if np.all(frame.scans["lidar_1"] == 10.0)]
    assert blind == [2, 3, 4, 12, 13, 14]


def test_beam_dropout_drops_about_its_fraction_in_bursts():
    out = run([BeamDropout(fraction=0.5, burst=8)])
    dropped = np.concatenate([frame.scans["lidar_1"] == 10.0 for frame in out])
    assert 0.4 < dropped.mean() < 0.6
    runs = np.diff(np.flatnonzero(np.diff(out[3].scans["lidar_1"] == 10.0)))
    assert np.all(runs[1:] % 8 == 0)  # whole bursts between the edges (the first may be cut)


def test_a_frozen_lidar_republishes_one_scan_while_the_other_runs():
    clean = frames()
    out = run([FrozenLidar(keys=("lidar_2",), after=3, duration=5)])
    for frame in out:
        expected = clean[3] if 3 <= frame.step < 8 else clean[frame.step]
        np.testing.assert_array_equal(frame.scans["lidar_2"], expected.scans["lidar_2"])
        np.testing.assert_array_equal(frame.scans["lidar_1"], clean[frame.step].scans["lidar_1"])


def test_outliers_replace_about_their_share_within_range():
    clean = frames()
    out = run([RangeOutliers(probability=0.1)])
    changed = np.concatenate([out[k].scans["lidar_1"] != clean[k].scans["lidar_1"]
                              for k in range(len(out))])
    assert 0.07 < changed.mean() < 0.13
    assert all(np.all((f.scans["lidar_1"] >= 0) & (f.scans["lidar_1"] < 10)) for f in out)


@pytest.mark.parametrize("fault", [lambda: Blind(every=None, probability=0.3, width=1.0),
                                   lambda: BeamDropout(), lambda: RangeOutliers()])
def test_same_seed_same_faults_other_seed_other_faults(fault):
    first, again, other = run([fault()], 1), run([fault()], 1), run([fault()], 2)
    same = all(np.array_equal(a.scans["lidar_1"], b.scans["lidar_1"])
               for a, b in zip(first, again, strict=True))
    differ = any(not np.array_equal(a.scans["lidar_1"], b.scans["lidar_1"])
                 for a, b in zip(first, other, strict=True))
    assert same and differ


def test_the_clean_arrays_are_never_changed():
    clean = frames()
    copies = [{k: v.copy() for k, v in f.scans.items()} for f in clean]
    list(apply_faults(clean, [Blind(every=1, offset=0), BeamDropout(), RangeOutliers()], 0, MAX))
    assert all(np.array_equal(f.scans[k], c[k]) for f, c in zip(clean, copies, strict=True)
               for k in MAX)


@pytest.mark.parametrize("build", [lambda: Blind(every=0), lambda: Blind(fill="nan"),
                                   lambda: BeamDropout(fraction=1.5), lambda: BeamDropout(burst=0),
                                   lambda: FrozenLidar(after=-1), lambda: RangeOutliers(-0.1)])
def test_bad_settings_are_config_errors(build):
    with pytest.raises(ConfigError):
        build()


def test_an_unknown_key_is_named():
    with pytest.raises(ConfigError, match="lidar_3"):
        run([Blind(keys=("lidar_3",))])


SCHEDULED = [Blind, ClockStall, ClockJump, ScanLoss]
BAD_SCHEDULES = [("every", 0, "integer >= 1"), ("every", True, "integer >= 1"),
                 ("stretch", 0, "integer >= 1"), ("offset", -1, "integer >= 0"),
                 ("offset", 1.5, "integer >= 0"), ("probability", 1.5, r"share in \[0, 1\]"),
                 ("probability", float("nan"), r"share in \[0, 1\]")]


@pytest.mark.parametrize(("fault", "name", "value", "expected"), [
    (fault, *case) for fault in SCHEDULED for case in BAD_SCHEDULES
    if case[0] in fault.__dataclass_fields__])
def test_every_scheduled_fault_names_a_bad_schedule_setting(fault, name, value, expected):
    with pytest.raises(ConfigError, match=f"^{name}: expected an? {expected}, got "):
        fault(**{name: value})


@pytest.mark.parametrize("fault", SCHEDULED, ids=lambda fault: fault.__name__)
def test_a_scheduled_fault_takes_no_schedule(fault):
    assert fault(every=None, probability=0.0).every is None
