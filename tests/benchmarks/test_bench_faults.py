"""Fault-matrix cells the estimators meet: after scans skipped (a blinded Lidar), lost (a
clock gap) or half their beams dropped, or a clock that jumps while the scans run on, the
pose is found again; after a long blind stretch it is found again or, where the first scan back
does not cover the place, reported lost (``bench_faults.verdict``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.datasets.faults import with_faults
from lidar_env.faults import ScanLoss
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")


CELLS = [(name, group, fault) for name in ("lidar_odometry", "slam") for group, fault in (
    ("open_cylinders/right_turn", "gaps"),
    ("open_cylinders/right_turn", "blind_3s"),
    ("open_cylinders/right_turn", "blind_100"),
    ("open_cylinders/right_turn", "dropout_half"),
    ("closed_to_open/zigzag", "blind_3s"),
    ("closed_to_open/zigzag", "dropout_half"),
    ("closed_to_open/zigzag", "gaps"),
    ("hallway/zigzag", "blind_3s"),  # along the corridor's axis the guess places the car
    ("hallway/zigzag", "gaps"),  # lost scans told from a stamp that jumped alone
)] + [
    # pc_fusion: scans lost or skipped; a turn while blind (the recovered motion is matched
    # again until it converges); half the beams dropped (a match fooled along the corridor does
    # not outvote the others); the longer guess not taken where only the stamp jumped
    ("pc_fusion", "closed_to_open/zigzag", "gaps"),
    ("pc_fusion", "hallway/zigzag", "gaps"),  # lost scans told from a stamp that jumped alone
    ("pc_fusion", "hallway/zigzag", "blind_3s"),
    ("pc_fusion", "closed_to_open/zigzag", "blind_3s"),
    ("pc_fusion", "closed_to_open/zigzag", "dropout_half"),
    ("pc_fusion", "hallway/zigzag", "clock_jump_3s"),
    ("pc_fusion", "closed_to_open/zigzag", "clock_jump_3s"),
    # pc_fusion after 10 s blind, where neither guess's match fits: the search on the keyframe
    ("pc_fusion", "open_cylinders/right_turn", "blind_100"),
    ("pc_fusion", "hallway/zigzag", "blind_100"),
    # icp: scans lost; 3 s of scans skipped through a 45-degree turn or a zigzag; 10 s skipped
    ("icp", "open_cylinders/right_turn", "gaps"),
    # icp: 10 scans lost where the scans pin little; the speed after the gap keeps its old part
    # along what the gap's match leaves free (the match's own slid 0.2 m across the drive)
    ("icp", "hallway/zigzag", "gaps"),
    ("icp", "closed_to_open/zigzag", "gaps"),
    ("icp", "open_cylinders/right_turn", "blind_3s"),
    ("icp", "open_cylinders/right_turn", "blind_100"),
    ("icp", "closed_to_open/zigzag", "blind_3s"),
    # icp down a corridor after 3 s and 10 s blind: not the corridor seen turned round
    ("icp", "hallway/zigzag", "blind_3s"),
    ("icp", "hallway/zigzag", "blind_100"),
]


@pytest.fixture(scope="module")
def drives() -> dict:
    return {group: bench.record_drive(group) for group in {group for _, group, _ in CELLS}}


@pytest.mark.parametrize(("name", "group", "fault"), CELLS)
def test_the_pose_is_found_again_after_the_fault(drives, name, group, fault) -> None:
    recording = drives[group]
    clean, _, _ = bench.run(name, recording, recording.truth[0])
    clean_jump, clean_final = bench.score(clean, recording.truth, recording.truth)
    run = bench.faulted_score(name, recording, fault)
    if fault.startswith("blind"):
        assert run.health["skipped_scans"] > 0 and run.health["blind_stretches"] > 0
    if run.return_jump is not None:  # a long stretch: the matrix's own rule (found or lost)
        assert bench.verdict(run, clean_jump, clean_final), (run, clean_jump, clean_final)
        return
    assert run.jump - clean_jump <= bench.JUMP_MARGIN, (run.jump, clean_jump)
    assert run.final <= bench.final_bound(clean_final), (run.final, clean_final)


def test_a_log_without_truth_is_scored_on_the_scans_kept(drives) -> None:
    recording = dataclasses.replace(drives["closed_to_open/zigzag"], truth=None)
    faulted = with_faults(recording, [ScanLoss(probability=0.0, every=60, offset=30,
                                               stretch=10)], seed=0)
    steps = bench.steps_of(recording, faulted)
    assert len(steps) == len(faulted) < len(recording)
    np.testing.assert_array_equal(recording.times[steps], faulted.times)


def test_truth_at_keyframes_scores_the_end_between_the_first_and_last_of_them() -> None:
    truth = np.full((5, 3), np.nan)
    truth[1] = (1.0, 0.0, np.pi / 2)
    truth[3] = (1.0, 2.0, np.pi / 2)  # 2 m ahead of keyframe 1, in its frame
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.5, 0.0, 0.0],
                      [9.0, 9.0, 0.0]])
    jump, final = bench.score(poses, poses, truth)
    assert jump == 0.0  # the steps are their own reference
    assert final == pytest.approx(0.5)  # 2.5 m ahead where the truth went 2 m


@pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("aces")),
                    reason="ACES and aces-corrected are absent from ../shared/data/radish")
def test_aces_carries_the_corrected_keyframes_at_their_scans() -> None:
    recording = bench.log_recording("aces", 0, 600)
    assert len(recording) == 600 and np.isfinite(recording.truth[0]).all()  # starts on truth
    known = np.flatnonzero(np.isfinite(recording.truth[:, 0]))
    assert 30 <= len(known) <= 60  # a keyframe every 0.5-1 m of ~40 m driven
    steps = np.linalg.norm(np.diff(recording.truth[known, :2], axis=0), axis=1)
    assert 0.3 < np.median(steps) < 1.5  # [m] the keyframe spacing, not a scan far off
    later = bench.log_recording("aces", 3000, 50)
    assert len(later) == 50 and np.isfinite(later.truth[0]).all()
    assert not np.array_equal(later.times, recording.times[:50])


def test_three_seconds_on_a_bursty_clock_are_three_seconds_of_scans() -> None:
    bursts = np.repeat(np.arange(0.0, 6.0, 0.4), 2) + np.tile([0.0, 0.001], 15)  # Intel-like
    period = bench.mean_period(bursts)
    assert period == pytest.approx(0.2, rel=0.05)  # the median interval is 1 ms
    blind = bench.faults_for(period, 1)["blind_3s"]()[0]
    assert blind.stretch * period == pytest.approx(3.0, rel=0.05)


def _faulted(recording, fault: str):
    period = bench.mean_period(recording.times)
    return with_faults(recording, bench.faults_for(period, recording.setup.n_lidars)[fault](),
                       seed=0)


def test_a_stretch_longer_than_3_s_is_long_and_measured_against_the_scan_before_it(
        drives) -> None:
    recording = drives["closed_to_open/zigzag"]
    after, covered = bench.long_stretch(_faulted(recording, "blind_100"), recording.truth)
    assert after == 160  # 100 blind scans from scan 60 on
    assert 0.0 < covered <= 1.0
    assert bench.long_stretch(_faulted(recording, "blind_3s"), recording.truth) is None
    # the same scans placed 1 m apart no longer cover each other
    moved = recording.truth.copy()
    moved[160:, 0] += 1.0
    assert bench.long_stretch(_faulted(recording, "blind_100"), moved)[1] < covered


def _run(final: float, return_jump: float | None, covered: float | None,
         lost: int = 0) -> object:
    return bench.FaultedRun(0.1, final, {"blind_stretches": 1, "lost_scans": lost}, 1.0,
                            return_jump, covered)


def test_after_a_long_stretch_a_place_not_covered_passes_only_if_reported_lost() -> None:
    clean_jump, clean_final = 0.0, 0.05  # final bound 0.2 m
    assert bench.verdict(_run(0.1, 0.05, 0.9), clean_jump, clean_final)
    assert not bench.verdict(_run(5.0, 0.05, 0.9, lost=1), clean_jump, clean_final)  # covered
    assert not bench.verdict(_run(5.0, 0.05, 0.1), clean_jump, clean_final)  # not said
    assert bench.verdict(_run(5.0, 0.05, 0.1, lost=1), clean_jump, clean_final)
    assert not bench.verdict(_run(0.1, 0.5, 0.9), clean_jump, clean_final)  # a jump on return
    assert not bench.verdict(_run(5.0, None, None, lost=1), clean_jump, clean_final)  # short


@pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("aces")),
                    reason="ACES and aces-corrected are absent from ../shared/data/radish")
def test_a_single_lidar_frozen_while_driving_is_skipped_and_the_car_found_after() -> None:
    # ACES from scan 3000: the robot drives on through a 3 s freeze of its only Lidar;
    # matched as a stop, the repeats left lidar_odometry 1.11 m off at the end
    recording = bench.log_recording("aces", 3000, 600)
    truth = recording.truth
    clean, _, _ = bench.run("lidar_odometry", recording, bench.start_of(truth))
    frozen = bench.faulted_score("lidar_odometry", recording, "frozen", clean)
    assert frozen.health["frozen_scans"] >= 10 and frozen.health["skipped_scans"] >= 10
    assert frozen.final <= bench.final_bound(bench.score(clean, clean, truth)[1])
    assert frozen.jump <= bench.JUMP_MARGIN


@pytest.mark.parametrize("spec", ["", ":3000", "aces:x", "aces:-5", "aces:3.5"])
def test_a_log_window_that_is_not_name_colon_scan_is_refused(
        spec: str, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as refused:
        bench.main(["--groups", "--logs", spec])
    assert refused.value.code == 2
    assert "expected NAME:SCAN" in capsys.readouterr().err


@pytest.mark.parametrize("count", ["0", "-3", "many"])
def test_log_scans_below_one_are_refused(count: str, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as refused:
        bench.main(["--groups", "--log-scans", count])
    assert refused.value.code == 2
    assert "expected an integer >= 1" in capsys.readouterr().err


def test_a_log_window_reads_its_name_and_first_scan_and_an_absent_log_is_skipped(
        capsys: pytest.CaptureFixture) -> None:
    assert bench.log_window("intel:3000") == ("intel", 3000)
    assert bench.log_window("aces") == ("aces", 0)
    assert bench.main(["--groups", "--logs", "nolog:10", "--estimators", "icp"]) == 0
    out = capsys.readouterr().out
    assert "nolog:10 skipped" in out and "0 of 0 runs" in out
