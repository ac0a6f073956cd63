"""The level test of ``verify`` against statistics with known truth.

:func:`~robocal_uncertainty.uncertainty.sessions.level.check_level` pools held-out fold levels and measures
their dispersion (their relative variance over the normal-theory ``2 / nu``);
:func:`~robocal_uncertainty.uncertainty.sessions.level.level_test` F-tests a check's level against it. Here
the fold and check levels are mean squares of drawn errors (no robot: the statistics alone),
so the truth is known: the dispersion of independent normal components is 1, of components
equal within a pose 3 (a pose then carries one degree of freedom, not three), of Student-t
components with 10 degrees of freedom ``(kurtosis - 1) / 2 = 1.5``; a same-session check of
normal errors is rejected in 5 % of draws at every check size, and the power against a larger
error level grows with the check. Measured (``python -m pytest -q -m slow
test/core/test_level_test.py -s``), false alarms at 10 / 50 / 200 poses: errors shared by a
pose's axes 7-8 % (component-kurtosis factor alone 15-17 %), heavy-tailed poses 10-13 %
(15-22 %): the dispersion measured on 53 poses is itself uncertain, and that is not propagated.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from robocal_uncertainty.core.session import ValidatedLevel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sessions.level import check_level, level_test


def _fold(errors: np.ndarray) -> SimpleNamespace:
    """A fold check's level (mean square per component, nothing re-registered) of errors (n, 3)."""
    level = float(np.mean(errors**2))
    return SimpleNamespace(
        level=level,
        level_dof=float(errors.size),
        level_trace=float(errors.size),
        level_z=(errors / np.sqrt(level)).reshape(-1),
        n_poses=errors.shape[0],
    )


def _draw(rng: np.random.Generator, n: int, kind: str) -> np.ndarray:
    if kind == "normal":
        return rng.standard_normal((n, 3))
    if kind == "pose":  # one error per pose, equal on the three axes
        return np.repeat(rng.standard_normal((n, 1)), 3, axis=1)
    if kind == "t10":
        return rng.standard_t(10, (n, 3))
    # Correlated within a pose (a common part) and a pose-to-pose scale: heavy-tailed poses.
    scale = np.exp(0.4 * rng.standard_normal((n, 1)))
    return scale * (rng.standard_normal((n, 1)) + 0.7 * rng.standard_normal((n, 3)))


@pytest.mark.parametrize(("kind", "expected"), [("normal", 1.0), ("pose", 3.0), ("t10", 1.5)])
def test_dispersion_of_fold_levels_matches_the_analytic_value(kind: str, expected: float) -> None:
    rng = np.random.default_rng(11)
    folds = [_fold(_draw(rng, 10, kind)) for _ in range(1200)]
    level = check_level(folds, repeats=1)  # type: ignore[arg-type]
    assert level.dispersion == pytest.approx(expected, rel=0.15)
    assert level.dof_factor == pytest.approx(min(1.0, 1.0 / expected), rel=0.15)
    assert level.level == pytest.approx(np.mean([f.level for f in folds]), rel=1e-12)


def test_repeated_splits_count_one_split_of_poses() -> None:
    rng = np.random.default_rng(3)
    errors = rng.standard_normal((50, 3))
    folds = []
    for _ in range(4):
        order = rng.permutation(50)
        folds += [_fold(errors[part]) for part in np.array_split(order, 5)]
    level = check_level(folds, repeats=4)  # type: ignore[arg-type]
    assert (level.folds, level.poses, level.repeats) == (5, 50, 4)
    assert level.dof == pytest.approx(150.0)  # one split's equations: the same 50 poses each time
    assert level.level == pytest.approx(float(np.mean(errors**2)), rel=1e-12)
    with pytest.raises(ConfigError, match="cannot come from 3 splits"):
        check_level(folds[:19], repeats=3)  # type: ignore[arg-type]


def test_files_without_a_dispersion_keep_the_kurtosis_factor() -> None:
    old = {"level": 1e-7, "dof": 100.0, "kurtosis": 5.0, "folds": 5, "poses": 53, "seed": 0}
    level = ValidatedLevel.from_dict(old)
    assert level.dispersion is None and level.repeats == 1
    assert level.dof_factor == pytest.approx(0.5)
    new = ValidatedLevel(1e-7, 100.0, 3.0, 5, 53, 0, 4, 2.5)
    assert ValidatedLevel.from_dict(new.to_dict()) == new
    assert new.dof_factor == pytest.approx(0.4)


def _false_alarms(
    kind: str, sizes: tuple[int, ...], ratio: float, *, measured: bool, runs: int = 1500
) -> dict[int, float]:
    """Rejection rate of checks of `sizes` poses against a 53-pose calibration's validated level.

    Each run: 53 calibration poses, 4 random 5-fold splits (the validated level), then one check
    per size of fresh poses whose errors are `ratio` times the calibration session's.
    `measured` False drops the dispersion (the component-kurtosis factor of older files).
    """
    rng = np.random.default_rng([7, len(kind), int(ratio * 100)])
    rejected = dict.fromkeys(sizes, 0)
    for _ in range(runs):
        errors = _draw(rng, 53, kind)
        folds = []
        for _ in range(4):
            order = rng.permutation(53)
            folds += [_fold(errors[part]) for part in np.array_split(order, 5)]
        reference = check_level(folds, repeats=4)  # type: ignore[arg-type]
        if not measured:
            reference = ValidatedLevel(reference.level, reference.dof, reference.kurtosis, 5, 53)
        for n in sizes:
            check = ratio * _draw(rng, n, kind)
            outcome = level_test(float(np.mean(check**2)), float(check.size), reference)
            rejected[n] += outcome.p_value < 0.05
    return {n: count / runs for n, count in rejected.items()}


@pytest.mark.slow
def test_same_session_false_alarms_are_five_percent_at_every_check_size() -> None:
    sizes = (10, 20, 50, 200)
    rates = _false_alarms("normal", sizes, 1.0, measured=True)
    for n in sizes:
        assert 0.03 <= rates[n] <= 0.07, (n, rates)  # nominal 5 %; binomial sd 0.56 % over 1500 runs


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "bound"), [("pose", 0.10), ("mixed", 0.15)])
def test_the_dispersion_removes_most_false_alarms_of_errors_shared_within_a_pose(kind: str, bound: float) -> None:
    """Errors shared by a pose's axes (kurtosis 3 per component): the component-kurtosis factor
    alone rejects far too often; the measured dispersion brings it down, but not to 5 %: the
    dispersion is itself estimated from 53 poses and its uncertainty is not propagated (a
    limit the test states rather than hides)."""
    sizes = (10, 50, 200)
    measured = _false_alarms(kind, sizes, 1.0, measured=True, runs=800)
    kurtosis_only = _false_alarms(kind, sizes, 1.0, measured=False, runs=800)
    print(kind, "dispersion", measured, "kurtosis only", kurtosis_only)
    for n in sizes:
        assert measured[n] <= bound, (n, measured)
        assert kurtosis_only[n] >= measured[n] + 0.03, (n, measured, kurtosis_only)


@pytest.mark.slow
def test_power_does_not_fall_as_the_check_grows() -> None:
    sizes = (10, 20, 50, 200)
    rates = _false_alarms("mixed", sizes, 1.5, measured=True, runs=600)
    assert rates[10] <= rates[20] + 0.03 <= rates[50] + 0.06 <= rates[200] + 0.09, rates
    assert rates[200] >= 0.8, rates
