"""The per-source random stream both Monte Carlos (calibration, section inspection) draw from."""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.montecarlo.engine import block_rng
from robocal_uncertainty.montecarlo.streams import source_generator


def test_a_source_draws_from_the_block_and_source_keyed_seed_sequence() -> None:
    """Independent reference: numpy's own SeedSequence with the documented spawn key."""
    expected = np.random.default_rng(np.random.SeedSequence(11, spawn_key=(3, 7))).random(5)
    np.testing.assert_array_equal(source_generator(block_rng(11, 3), 7).random(5), expected)
    # The s-th child of the block's SeedSequence (what SeedSequence.spawn would give).
    child = np.random.SeedSequence(11, spawn_key=(3,)).spawn(8)[7]
    np.testing.assert_array_equal(np.random.default_rng(child).random(5), expected)


def test_streams_do_not_depend_on_what_the_block_generator_drew() -> None:
    rng = block_rng(2, 0)
    first = source_generator(rng, 1).random(4)
    rng.random(100)  # another source, or the block itself, drawing first
    np.testing.assert_array_equal(source_generator(rng, 1).random(4), first)
    assert not np.array_equal(source_generator(rng, 2).random(4), first)
    assert not np.array_equal(source_generator(block_rng(2, 1), 1).random(4), first)


def test_a_generator_without_a_seed_sequence_seeds_the_stream_from_its_own_draws() -> None:
    """A legacy-seeded bit generator has no SeedSequence: reproducible from its state."""

    def legacy() -> np.random.Generator:
        bit_generator = np.random.MT19937()
        bit_generator._legacy_seeding(5)
        return np.random.Generator(bit_generator)

    a = source_generator(legacy(), 4).random(3)
    np.testing.assert_array_equal(source_generator(legacy(), 4).random(3), a)
    assert not np.array_equal(source_generator(legacy(), 5).random(3), a)
