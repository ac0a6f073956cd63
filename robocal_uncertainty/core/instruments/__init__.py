"""Measuring instruments: each one's error model, in one place, shared by every consumer.

- :mod:`.laser_tracker`: :class:`TrackerNoise`, uniform within the MPE +-(a + b L);
- :mod:`.encoders`: :class:`EncoderNoise`, joint readings, revolute [rad] and linear [m];
- :mod:`.cmm`: :class:`CmmInstrument` (MPE A + L/K, thermal, probing, algorithm) and its
  per-point :class:`ErrorSource` set.

Each instrument is a frozen dataclass whose error model is a ``montecarlo`` distribution: the
GUM variance (the distribution's covariance) and the Monte Carlo draws (its samples) come from
one definition, for the simulation, the calibration sources and section inspection alike.
A new instrument is one module here plus its line below.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.core.instruments.cmm import (
        SOURCE_NAMES,
        CmmInstrument,
        ErrorSource,
        SourceKind,
        draw_bound,
        load_instrument,
        point_displacements,
        point_error_sources,
        reference_paper_instrument,
    )
    from robocal_uncertainty.core.instruments.encoders import LINEAR_ENCODER_HALF_WIDTH, EncoderNoise
    from robocal_uncertainty.core.instruments.laser_tracker import TrackerNoise

__all__ = [
    "LINEAR_ENCODER_HALF_WIDTH",
    "SOURCE_NAMES",
    "CmmInstrument",
    "EncoderNoise",
    "ErrorSource",
    "SourceKind",
    "TrackerNoise",
    "draw_bound",
    "load_instrument",
    "point_displacements",
    "point_error_sources",
    "reference_paper_instrument",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
