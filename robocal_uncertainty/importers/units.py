"""Unit names accepted in measurement files and exact conversion of decimal text to SI.

Lengths are converted from their decimal text with exact decimal arithmetic and a single
final rounding, so ``"2336.7643"`` mm gives exactly ``float("2.3367643")`` m. Angles in
degrees are converted with :func:`numpy.deg2rad` (multiplication by pi/180).
"""

from __future__ import annotations

import math
from decimal import Decimal, InvalidOperation, localcontext
from typing import Literal

import numpy as np

__all__ = ["ANGLE_UNITS", "LENGTH_UNITS", "UnitKind", "canonical_unit", "to_si"]

UnitKind = Literal["length", "angle"]

LENGTH_UNITS: dict[str, int] = {"m": 0, "mm": -3, "um": -6}
"""Length units and their power of ten relative to the metre."""

ANGLE_UNITS: tuple[str, ...] = ("rad", "deg")
"""Angle units (converted to rad)."""

_ALIASES = {"µm": "um", "μm": "um", "micron": "um", "degree": "deg", "degrees": "deg"}


def canonical_unit(unit: str, kind: UnitKind) -> str | None:
    """Return the canonical name of `unit` for a quantity of `kind`, or None if unsupported."""
    name = _ALIASES.get(unit.strip(), unit.strip())
    allowed = tuple(LENGTH_UNITS) if kind == "length" else ANGLE_UNITS
    return name if name in allowed else None


def to_si(text: str, unit: str) -> float:
    """Convert the decimal number `text` given in the canonical `unit` to m or rad.

    Raises
    ------
    ValueError
        If `text` is not a finite decimal number.
    """
    try:
        value = Decimal(text.strip())
    except InvalidOperation:
        msg = f"{text!r} is not a number"
        raise ValueError(msg) from None
    if not value.is_finite():
        msg = f"{text!r} is not finite"
        raise ValueError(msg)
    if unit in LENGTH_UNITS:
        with localcontext() as context:
            context.prec = max(28, len(value.as_tuple().digits) + 2)
            result = float(value.scaleb(LENGTH_UNITS[unit]))
    elif unit == "rad":
        result = float(value)
    elif unit == "deg":
        result = float(np.deg2rad(float(value)))
    else:
        msg = f"unknown unit {unit!r}"
        raise ValueError(msg)
    if not math.isfinite(result):
        msg = f"{text!r} overflows a float"
        raise ValueError(msg)
    return result
