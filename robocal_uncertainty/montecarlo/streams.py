"""One random stream per source per block, shared by every Monte Carlo of the package.

A Monte Carlo block ``b`` draws from ``default_rng(SeedSequence(seed, spawn_key=(b,)))``
(:func:`~robocal_uncertainty.montecarlo.engine.block_rng`). Inside the block, each input
source gets its own generator, keyed by the block and the source:
``SeedSequence(seed, spawn_key=(b, stream))``. A source's draws then depend only on the
seed, the block and its own key, not on which other sources run or in which order: adding,
removing or reordering a source never moves another one's draws. The calibration sources
key by a stable id of their name, section inspection by the CMM source's index.
"""

from __future__ import annotations

import numpy as np

__all__ = ["source_generator"]


def source_generator(block_rng: np.random.Generator, stream: int) -> np.random.Generator:
    """The generator of source `stream` inside the block whose generator is `block_rng`.

    Parameters
    ----------
    block_rng : numpy.random.Generator
        The block's generator; built from a ``SeedSequence`` (as every block of the engine).
    stream : int
        The source's key, >= 0 (its spawn-key element).

    Returns
    -------
    numpy.random.Generator
        ``default_rng(SeedSequence(entropy, spawn_key=(*block_key, stream), pool_size=...))``
        from the block's own SeedSequence, so a worker needs nothing more than the block's
        generator. A generator not built from a SeedSequence (a legacy-seeded bit generator)
        seeds the sequence from its own first four draws instead: still reproducible, but
        it advances `block_rng`.
    """
    bit_generator = block_rng.bit_generator
    sequence = getattr(bit_generator, "seed_seq", None) or getattr(bit_generator, "_seed_seq", None)
    if not isinstance(sequence, np.random.SeedSequence):
        sequence = np.random.SeedSequence(block_rng.integers(0, 2**63, size=4))
    child = np.random.SeedSequence(
        sequence.entropy, spawn_key=(*sequence.spawn_key, int(stream)), pool_size=sequence.pool_size
    )
    return np.random.default_rng(child)
