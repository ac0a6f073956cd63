"""Checks the instruments share on their magnitudes."""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["is_real"]


def is_real(value: object) -> bool:
    """A real number (not a bool): what the finiteness checks of a magnitude may compare."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
