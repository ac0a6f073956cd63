"""Is a Monte Carlo result a statement at all? Checks that need no convergence test.

A fixed number of trials runs no convergence test (JCGM 101 §7.9 is the adaptive procedure),
so nothing inside the run says whether its numbers mean anything. Two checks do:

* **Enough trials for the interval asked** (JCGM 101 §7.2.2: M large compared with
  ``1/(1 - p)``). Below ``2/(1 - p)`` trials a probabilistically symmetric interval has less
  than one trial beyond either end: it is the sample range, not a ``p`` interval, and no
  statement is made (:func:`interval_trial_floor`). Below ``100/(1 - p)`` (2 000 at 95 %, 50
  trials beyond each end; the content of an interval from M draws scatters by
  ``sqrt(p (1 - p) / M)``, 0.5 % at 2 000) the interval is stated with a warning
  (:func:`recommended_trials`).
* **Agreement with the run's own first-order (GUM) statement.** The GUM standard uncertainty
  of the smooth sources is a linearisation at the calibration; the Monte Carlo of the same
  calibration spreads more only where a non-smooth source (lambda, number and choice of
  poses) adds to it or the model is strongly nonlinear over the spread, and never by orders of
  magnitude. A ratio beyond :data:`GUM_DISAGREEMENT_FACTOR` either way means the trials did not
  re-identify the same solution (diverged, another local minimum, a robot 1000 times too
  small): the run is reported as not converged and its numbers are not a statement.
  The factor is wide on purpose: over the demo's scenario (its non-smooth sources give the
  largest ratio, 2.1), simulated UR10 and paper-arm campaigns of 10 to 53 poses with and
  without unmodelled joint errors, and the real UR10 series and its subsets (points and
  6-DOF), the ratio stayed within 0.94 to 2.1 (``benchmarks/gum_agreement_study.py --seeds
  10``), while the failures it is meant for are off by 10^8 (a robot 1000 times too small) or
  10^10 (a 10-pose subset whose trials diverged).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "GUM_DISAGREEMENT_FACTOR",
    "gum_disagreements",
    "interval_trial_floor",
    "recommended_trials",
    "spread_disagreements",
    "too_few_trials_note",
]

GUM_DISAGREEMENT_FACTOR = 10.0
"""Largest ratio (either way) of a Monte Carlo standard uncertainty to the GUM one of the same
run that is still a converged statement (see the module documentation for the evidence)."""

_AXES = ("x", "y", "z")


def interval_trial_floor(coverage: float) -> int:
    """Fewest trials for which a ``coverage`` interval has a trial beyond each end: ``2/(1-p)``."""
    return math.ceil(2.0 / (1.0 - coverage) - 1e-9)


def recommended_trials(coverage: float) -> int:
    """Trials below which an interval is stated with a warning: ``100/(1-p)`` (2 000 at 95 %)."""
    return math.ceil(100.0 / (1.0 - coverage) - 1e-9)


def too_few_trials_note(n_trials: int, coverage: float) -> str | None:
    """The warning for a fixed run of `n_trials` below :func:`recommended_trials`, or None."""
    recommended = recommended_trials(coverage)
    if n_trials >= recommended:
        return None
    return (
        f"a {coverage * 100:g} % interval from {n_trials} trials: JCGM 101 7.2 asks for many more than "
        f"1/(1-p) = {1.0 / (1.0 - coverage):.3g}; its ends rest on {int(n_trials * (1.0 - coverage) / 2.0)} trials "
        f"each (give --trials {recommended} or more, or --trials auto)"
    )


def spread_disagreements(
    mc_std: NDArray[np.float64],
    gum_std: NDArray[np.float64],
    labels: Sequence[str],
    *,
    factor: float = GUM_DISAGREEMENT_FACTOR,
) -> tuple[str, ...]:
    """Where a Monte Carlo standard uncertainty and the first-order one differ by more than `factor`.

    Parameters
    ----------
    mc_std : ndarray, shape (n, 3) [m]
        Monte Carlo standard uncertainties along x, y, z.
    gum_std : ndarray, shape (n, 3) [m]
        First-order (GUM) standard uncertainties of the same outputs; an entry that is not
        finite and positive has nothing to compare with and is skipped.
    labels : sequence of str, length n
        How each row is named in the message (e.g. ``test configuration 1``).
    factor : float
        Largest accepted ratio either way.

    Returns
    -------
    tuple of str
        One line per row with a disagreement or a non-finite Monte Carlo value.
    """
    problems = []
    for label, mc, gum in zip(labels, np.asarray(mc_std, dtype=np.float64), np.asarray(gum_std, dtype=np.float64)):
        if not np.isfinite(mc).all():
            problems.append(f"{label}: the Monte Carlo gave non-finite values")
            continue
        worst = None
        for j in range(len(_AXES)):
            if not (np.isfinite(gum[j]) and gum[j] > 0.0):
                continue  # no first-order value to compare with (no smooth source)
            ratio = mc[j] / gum[j]
            off = max(ratio, 1.0 / ratio) if ratio > 0.0 else math.inf
            if off > factor and (worst is None or off > worst[0]):
                worst = (off, j, ratio)
        if worst is not None:
            _, j, ratio = worst
            problems.append(
                f"{label}: Monte Carlo u = {mc[j] * 1e3:.4g} mm against its first-order (GUM) "
                f"u = {gum[j] * 1e3:.4g} mm along {_AXES[j]} (ratio {ratio:.3g}, more than {factor:g} either way)"
            )
    return tuple(problems)


def gum_disagreements(poses: Sequence[Any], *, factor: float = GUM_DISAGREEMENT_FACTOR) -> tuple[str, ...]:
    """Where the Monte Carlo position u and the run's GUM u differ by more than `factor`.

    Parameters
    ----------
    poses : sequence of PoseUncertainty
        Each with ``axes`` (Monte Carlo summaries [m]) and ``gum`` (first-order statement).
    factor : float
        Largest accepted ratio either way.

    Returns
    -------
    tuple of str
        One line per test configuration with a disagreement (or a non-finite Monte Carlo
        value); empty when every axis agrees or has no GUM value to compare with.
    """
    mc = np.empty((len(poses), len(_AXES)))
    gum = np.empty((len(poses), len(_AXES)))
    for i, pose in enumerate(poses):
        mc[i] = [a.standard_uncertainty for a in pose.axes]
        if not np.isfinite(np.asarray(pose.mean, dtype=np.float64)).all():
            mc[i] = np.nan  # a non-finite mean is no statement either
        gum[i] = np.asarray(pose.gum.standard_uncertainty, dtype=np.float64)
    labels = [f"test configuration {i + 1}" for i in range(len(poses))]
    return spread_disagreements(mc, gum, labels, factor=factor)
