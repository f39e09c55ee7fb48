"""The batched env draws its range noise and its movers' waypoints with the compiled PCG64 draws
of :mod:`lidar_env.vector.draws`, over each sub-env's ``numpy.random.Generator`` state: they must
be numpy's, bit for bit, and leave the generator's state where numpy's would (its ziggurat's rare
rejections and tail included, which 200,000 draws reach a few thousand times), or no batched
observation could match a single env's."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from lidar_env.core.errors import ArgumentTypeError
from lidar_env.vector.draws import (
    fill_standard_normal_pair,
    fill_standard_normals,
    fill_uniforms,
    state_address,
    state_words,
    words_at,
)


@pytest.mark.parametrize("count", [1, 720, 200_000])
def test_compiled_draws_are_numpys_and_advance_the_generator_alike(count: int) -> None:
    for seed in range(3):
        numpy_rng, compiled_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        expected = numpy_rng.standard_normal(count), numpy_rng.random(count)
        got = np.empty(count), np.empty(count)
        words = state_words(compiled_rng)
        fill_standard_normals(words, got[0])
        fill_uniforms(words, got[1])
        for name, value, reference in zip(
            ("standard_normal", "random"), got, expected, strict=True
        ):
            assert value.tobytes() == reference.tobytes(), f"seed {seed}: {name}"
        # the words are the generator's own state: numpy carries on from where they stopped
        assert compiled_rng.bit_generator.state == numpy_rng.bit_generator.state
        assert compiled_rng.standard_normal() == numpy_rng.standard_normal()


def test_the_tail_and_the_wedges_of_the_ziggurat_are_drawn_as_numpy_draws_them() -> None:
    # beyond the ziggurat's base (|x| > 3.654, the tail loop) and the wedge rejections: a
    # million draws hold a few hundred tail values
    numpy_rng, compiled_rng = np.random.default_rng(11), np.random.default_rng(11)
    expected = numpy_rng.standard_normal(1_000_000)
    got = np.empty_like(expected)
    fill_standard_normals(state_words(compiled_rng), got)
    assert np.count_nonzero(np.abs(expected) > 3.6541528853610088) > 100
    assert got.tobytes() == expected.tobytes()


@pytest.mark.parametrize("count", [0, 1, 720, 1_000_000])
def test_paired_draws_are_each_generators_own(count: int) -> None:
    # two generators drawn interleaved: each block is numpy's for its generator, the tail and
    # wedge rejections (which take each stream its own number of outputs) included
    numpy_rngs = np.random.default_rng(21), np.random.default_rng(22)
    compiled_rngs = np.random.default_rng(21), np.random.default_rng(22)
    got = np.empty(count), np.empty(count)
    fill_standard_normal_pair(state_words(compiled_rngs[0]), got[0],
                              state_words(compiled_rngs[1]), got[1])
    for numpy_rng, compiled_rng, values in zip(numpy_rngs, compiled_rngs, got, strict=True):
        assert values.tobytes() == numpy_rng.standard_normal(count).tobytes()
        assert compiled_rng.bit_generator.state == numpy_rng.bit_generator.state


def test_the_words_keep_their_generator_alive() -> None:
    words = state_words(np.random.default_rng(5))  # the only reference to the generator
    others = [np.random.default_rng(seed) for seed in range(100, 400)]  # reuse freed memory
    got = np.empty(1_000)
    fill_standard_normals(words, got)
    assert got.tobytes() == np.random.default_rng(5).standard_normal(1_000).tobytes()
    assert len(others) == 300


def test_another_bit_generator_is_refused_by_name() -> None:
    with pytest.raises(ArgumentTypeError, match="expected a numpy PCG64 generator, got Philox"):
        state_words(np.random.Generator(np.random.Philox(0)))


@njit(cache=True)
def _normals_at(address: np.uint64, out: np.ndarray) -> None:
    fill_standard_normals(words_at(address), out)


def test_the_words_at_a_generators_address_are_its_state() -> None:
    numpy_rng, compiled_rng = np.random.default_rng(3), np.random.default_rng(3)
    got = np.empty(720)
    _normals_at(np.uint64(state_address(compiled_rng)), got)
    assert got.tobytes() == numpy_rng.standard_normal(720).tobytes()
    assert compiled_rng.bit_generator.state == numpy_rng.bit_generator.state
