"""The heading search's and the refinement starts' float paths, and the centred spectrum's
bare reductions, against the numpy forms they replaced, bit for bit (numpy's
per-call cost on a few numbers was most of their time)."""

from __future__ import annotations

import numpy as np
import scipy.fft
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.curve_refinement import PRIOR_SIGMA, pose_difference
from estimators.matching.rotation import _subbin_peak, centred_spectrum, resolve_half_turn
from estimators.matching.rotation_pc import refinement_starts
from lidar_env.core.se2 import wrap_angle

angles = st.floats(-10.0, 10.0, allow_nan=False)


def _resolve_half_turn_arrays(angle_mod_pi: float, reference: float) -> float:
    candidates = wrap_angle(np.array([angle_mod_pi, angle_mod_pi + np.pi]))
    return float(candidates[np.argmin(np.abs(wrap_angle(candidates - reference)))])


def _subbin_peak_arrays(correlation: np.ndarray) -> tuple[float, float]:
    n = len(correlation)
    k = int(np.argmax(correlation))
    left, centre, right = correlation[(k - 1) % n], correlation[k], correlation[(k + 1) % n]
    curvature = left - 2.0 * centre + right
    offset = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
    return k + float(np.clip(offset, -0.5, 0.5)), float(centre)


@settings(max_examples=300, deadline=None)
@given(angles, angles)
def test_resolve_half_turn_is_the_array_form_bit_for_bit(angle: float, reference: float) -> None:
    assert resolve_half_turn(angle, reference) == _resolve_half_turn_arrays(angle, reference)


def test_resolve_half_turn_takes_the_first_candidate_on_a_tie() -> None:
    # 0 and pi are equally far from pi/2: argmin's first, the angle itself
    assert resolve_half_turn(0.0, np.pi / 2) == _resolve_half_turn_arrays(0.0, np.pi / 2)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=3, max_size=40))
def test_subbin_peak_is_the_array_form_bit_for_bit(values: list[float]) -> None:
    correlation = np.array(values)
    assert _subbin_peak(correlation) == _subbin_peak_arrays(correlation)


poses = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), angles)


@settings(max_examples=300, deadline=None)
@given(poses, poses, st.floats(0.0, 0.2))
def test_refinement_starts_decides_as_the_array_form(
    start: tuple[float, float, float], prior: tuple[float, float, float], scale: float
) -> None:
    start_array = np.array(start)
    # priors near the start too, where the decision is made
    near = start_array + scale * (np.array(prior) - start_array)
    for candidate in (np.array(prior), near):
        expected = bool(np.any(np.abs(pose_difference(start_array, candidate)) > PRIOR_SIGMA))
        starts = refinement_starts(start_array, candidate)
        assert len(starts) == (2 if expected else 1)
        assert starts[0] is start_array
    assert refinement_starts(start_array, None) == [start_array]


@settings(max_examples=100, deadline=None)
@given(st.integers(8, 64), st.integers(1, 8), st.integers(0, 2**32 - 1), st.floats(0.0, 6.0))
def test_centred_spectrum_is_the_mean_and_sum_form_bit_for_bit(
    n: int, width: int, seed: int, decades: float
) -> None:
    signal = np.log1p(np.random.default_rng(seed).random((n, width)) * 10.0**decades)
    centred = signal - signal.mean(axis=0)
    result = centred_spectrum(signal)
    assert np.array_equal(result.transform, scipy.fft.rfft(centred, axis=0, workers=1))
    assert result.energy == float(np.sum(centred * centred))
