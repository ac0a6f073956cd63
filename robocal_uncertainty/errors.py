"""One error hierarchy for the whole package.

The command line catches :class:`CalibError`, prints its one-line message and exits 1;
nodes log it. Every message names the offending value, argument or path.
"""

from __future__ import annotations

__all__ = [
    "BagError",
    "CalibError",
    "CampaignError",
    "ConfigError",
    "ConvergenceError",
    "IdentifiabilityError",
    "InputError",
]


class CalibError(Exception):
    """Base of every error this package raises on purpose."""


class ConfigError(CalibError):
    """A robot or run configuration is missing fields, has unknown units or bad values."""


class InputError(CalibError):
    """Measurement data are malformed: NaN/inf, wrong shapes, wrong joint names."""


class CampaignError(InputError):
    """A campaign file cannot be read or is not a campaign."""


class BagError(CampaignError):
    """An MCAP/rosbag2 file is corrupt, has wrong topics or message types."""


class IdentifiabilityError(CalibError):
    """The pose set cannot identify the requested parameters (too few or degenerate poses)."""


class ConvergenceError(CalibError):
    """An iterative solver did not converge and the caller asked for a hard failure."""
