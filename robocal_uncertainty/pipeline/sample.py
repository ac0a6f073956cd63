"""Compatibility alias: :class:`CalibrationSample` lives in :mod:`robocal_uncertainty.core.sample`.

It moved down to ``core`` so that ``bagio`` (messages <-> dataclasses) no longer imports
``pipeline``, which imports ``bagio``.
"""

from robocal_uncertainty.core.sample import CalibrationSample

__all__ = ["CalibrationSample"]
