"""Estimators on the real Radish logs: setup from the log, no odometry, relation accuracy on
the first scans of ACES, and Intel's pseudo ground truth lined up with its scans."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators import make
from estimators.datasets.carmen import load_log
from estimators.datasets.real_log import (
    pseudo_truth_relations,
    run_on_log,
    score_relations,
    setup_from_log,
)
from estimators.evaluation.relations import load_relations, match_times
from estimators.paths import SHARED_DATA

DATA = SHARED_DATA / "radish"
pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not DATA.is_dir(), reason=f"real logs absent: expected them in {DATA}"),
]
#: ACES's first 300 scans (~50 s of driving, 50 relations): short enough for CI.
SCANS = 300


@pytest.fixture(scope="module")
def aces():
    return load_log(DATA / "aces.clf.bz2")


def test_setup_from_the_log(aces):
    setup = setup_from_log(aces)
    assert setup.n_lidars == 1
    np.testing.assert_array_equal(setup.mounts, [[0.0, 0.0, 0.0]])  # FLASER offset 0.0
    assert len(setup.beam_angles) == 180
    assert setup.max_range == 50.0  # the SICK saturation value written for "no return"


def test_estimators_never_read_odometry(aces):
    head = dataclasses.replace(aces, scans=aces.scans[:40])
    scrambled = dataclasses.replace(
        head,
        scans=[dataclasses.replace(s, logged_pose=s.logged_pose + 5.0) for s in head.scans],
        odometry=[],
    )
    for name in ("icp", "lidar_odometry"):
        clean = run_on_log(make(name), head)
        np.testing.assert_array_equal(clean.poses, run_on_log(make(name), scrambled).poses)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "max_error"), [("lidar_odometry", 0.05), ("icp", 0.10)])
def test_aces_local_relations(aces, name: str, max_error: float):
    run = run_on_log(make(name), aces, limit=SCANS)
    scores = score_relations(run, load_relations(DATA / "aces.relations"))
    assert scores["local"].count >= 30
    # Measured on these scans: lidar_odometry 0.037 m, icp 0.039 m; the bounds leave room for
    # platform float differences, not for a regression to dead reckoning (> 0.2 m).
    assert scores["local"].translation_mean < max_error
    assert scores["local"].rotation_mean < 1.0
    assert scores["local"].failure_rate <= 0.05


@pytest.mark.slow
def test_intel_pseudo_truth_lines_up_with_the_log():
    corrected = load_log(DATA / "intel-corrected.log.gz")
    relations = pseudo_truth_relations(corrected)
    assert set(relations) == {"consecutive", "1 s", "5 s"}
    assert np.all(relations["5 s"].t2 - relations["5 s"].t1 >= 5.0)
    times = load_log(DATA / "intel.clf.bz2").scan_times("logger")
    # Every SLAM keyframe is one of the log's scans (its stamps are rounded to 6 digits).
    match_times(times, relations["consecutive"].t1, tolerance=0.01)


def test_a_clock_that_runs_back_is_nudged_forward_with_a_warning(aces):
    from estimators.datasets.real_log import BackwardClockWarning

    head = aces.scans[:30]
    stamps = [s.logger_timestamp for s in head]
    stamps[10] = stamps[9] - 0.05  # a stamp that jumps back, as 631 of Intel's do
    tampered = dataclasses.replace(aces, scans=[
        dataclasses.replace(s, logger_timestamp=t) for s, t in zip(head, stamps, strict=True)])
    with pytest.warns(BackwardClockWarning, match="1 of the log's 30 'logger' stamps"):
        run = run_on_log(make("icp"), tampered, clock="logger")
    np.testing.assert_array_equal(run.times, stamps)  # scored on the logged stamps
    assert np.all(np.isfinite(run.poses)) and len(run.poses) == 30


def _flaser(n: int, t: float) -> str:
    return f"FLASER {n} {' '.join(['1.0'] * n)} 0 0 0 0 0 0 {t} host {t}\n"


def test_a_log_whose_laser_changes_names_the_first_line_that_differs(tmp_path) -> None:
    beams = tmp_path / "beams.log"
    beams.write_text(_flaser(180, 1.0) + _flaser(180, 1.1) + _flaser(181, 1.2) + _flaser(180, 1.3))
    with pytest.raises(ValueError, match=r"beams.log, line 3: beam geometry changes .*181 beams"):
        setup_from_log(load_log(beams))
    mount = tmp_path / "mount.log"
    mount.write_text(_flaser(180, 1.0) + "PARAM robot_frontlaser_offset 0.2\n"
                     + _flaser(180, 1.1) + _flaser(181, 1.2))
    with pytest.raises(ValueError, match=r"mount.log, line 3: laser mount changes"):
        setup_from_log(load_log(mount))
    steady = tmp_path / "steady.log"
    steady.write_text(_flaser(180, 1.0) + _flaser(180, 1.1))
    assert setup_from_log(load_log(steady)).sensors[0].n_beams == 180
