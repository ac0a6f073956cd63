"""What determines the result of one calibration uncertainty evaluation besides its data."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = ["EvaluationSettings"]


@dataclass(frozen=True)
class EvaluationSettings:
    """Everything that determines the result of :func:`evaluate_uncertainty` besides its data.

    The data are the model, the campaign, the test configurations and (optionally) an existing
    calibration; how the trials are run (workers, chunks, an executor, a progress callback)
    never changes the result and is given to :func:`evaluate_uncertainty` separately.

    Attributes
    ----------
    uncertainty : UncertaintySettings
        Sources and their models; default tracker and encoder noise at the seed's levels.
    lambda_ : {"auto", "gcv"} or float
        Lambda method of the calibration (when it is computed here).
    trials : int or "auto"
        Fixed number of trials, or the JCGM 101 §7.9 adaptive procedure.
    coverage : float
        Coverage probability p in (0, 1).
    seed : int
        Root seed; the result is reproducible from it.
    n_dig : int
        Significant digits of the adaptive procedure and the GUM validation.
    max_trials : int
        Cap of the adaptive procedure.
    block_size : int
        Trials per independent random stream (part of the result's identity).
    frame : {"measurement", "base"}
        Frame of the output positions. ``measurement``: the frame of the campaign's points, so
        results compare directly with measurements; for a tracker-frame campaign the
        uncertainty of the identified base enters. ``base``: the robot base frame (the
        identified base does not enter).
    orientation : bool
        Also evaluate the tool orientation (3 more columns per test configuration, see the
        module docstring); positions and parameters are the same either way, bit for bit.
        The adaptive procedure monitors the positions only.
    backend : {"numpy", "numba", "cupy", "auto"}
        Which trial kernels walk the chain (:mod:`robocal_uncertainty.kernels`): the same
        draws, the same result to rounding (1e-12 relative, tested), recorded in the result.
    """

    uncertainty: UncertaintySettings = field(default_factory=UncertaintySettings)
    lambda_: str | float = "auto"
    trials: int | str = 10_000
    coverage: float = 0.95
    seed: int = 0
    n_dig: int = 2
    max_trials: int = 2_000_000
    block_size: int = 10_000
    frame: str = "measurement"
    orientation: bool = True
    backend: str = "numpy"

    def replace(self, **keywords: Any) -> EvaluationSettings:
        """A copy with fields replaced; also takes the keyword names :func:`evaluate_uncertainty`
        had before this object (``settings`` for :attr:`uncertainty`, None meaning the default).

        Raises
        ------
        TypeError
            An unknown keyword.
        """
        changes: dict[str, Any] = {}
        for given, value in keywords.items():
            name = "uncertainty" if given == "settings" else given
            if name not in _EVALUATION_FIELDS:
                msg = f"evaluate_uncertainty() got an unexpected keyword argument {given!r}"
                raise TypeError(msg)
            changes[name] = UncertaintySettings() if given == "settings" and value is None else value
        return dataclasses.replace(self, **changes) if changes else self


_EVALUATION_FIELDS = frozenset(f.name for f in dataclasses.fields(EvaluationSettings))
