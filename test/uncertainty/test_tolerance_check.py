"""The three-way check against the statement's tolerance, against independent references.

``tolerance_check`` says drifted when a check's error ratio is significantly beyond the ratio
at which normal errors fill the statement's 95 % region to 91 %, consistent when its one-sided
95 % upper bound is within it, inconclusive otherwise. References: the tolerated ratio from the
normal and t quantiles by hand, the verdicts of drawn F statistics with known truth, and the
size a check needs by brute force over the sizes.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from robocal_uncertainty.core.session import ValidatedLevel
from robocal_uncertainty.uncertainty.sessions.level import tolerance_check


def _reference(dof: float = 200.0) -> ValidatedLevel:
    # dispersion 1: the dof are taken as they are (factor 1)
    return ValidatedLevel(level=1e-8, dof=dof, kurtosis=3.0, folds=5, poses=53, repeats=4, dispersion=1.0)


def test_tolerated_ratio_is_where_normal_errors_fill_the_region_to_91_percent() -> None:
    ref = _reference(200.0)
    check = tolerance_check(ref.level, 21.0, ref)
    t_limit = stats.t.ppf(0.975, 200.0)
    # at the tolerated ratio a normal component falls inside +-t_limit (in reference units) 91 % of the time
    inside = 2.0 * stats.norm.cdf(t_limit / check.tolerated_ratio) - 1.0
    assert abs(inside - 0.91) < 1e-9
    assert 1.15 < check.tolerated_ratio < 1.18


def test_a_ten_pose_check_cannot_tell_and_says_how_many_poses_would() -> None:
    ref = _reference(200.0)
    ten = tolerance_check(ref.level, 21.0, ref)  # 10 poses, 9 re-registered, errors as the calibration's
    assert ten.verdict == "inconclusive"
    assert ten.poses_needed is not None
    # brute force: the smallest size whose one-sided upper bound at ratio 1 is within the tolerance
    for n in range(4, 400):
        upper = np.sqrt(1.0 / stats.f.ppf(0.05, 3 * n - 9, 200.0))
        if upper <= ten.tolerated_ratio:
            assert n == ten.poses_needed
            break
    at_size = tolerance_check(ref.level, 3.0 * ten.poses_needed - 9, ref)
    below = tolerance_check(ref.level, 3.0 * (ten.poses_needed - 1) - 9, ref)
    assert at_size.verdict == "consistent"
    assert below.verdict == "inconclusive"


def test_no_size_can_tell_when_the_reference_itself_is_too_uncertain() -> None:
    ref = _reference(10.0)  # a validated level on 10 dof: its own uncertainty alone exceeds the tolerance
    assert tolerance_check(ref.level, 21.0, ref).poses_needed is None


def test_verdicts_of_drawn_checks_with_known_ratio() -> None:
    rng = np.random.default_rng(7)
    ref_dof, check_dof = 150.0, 141.0  # 50 poses
    ref = _reference(ref_dof)
    r_star = tolerance_check(ref.level, check_dof, ref).tolerated_ratio
    for ratio, wrong in ((1.0, "drifted"), (2.0, "consistent")):
        # the reference level is itself drawn: F = (chi2_c / nu_c) / (chi2_r / nu_r) times ratio^2
        f = ratio**2 * (rng.chisquare(check_dof, 800) / check_dof) / (rng.chisquare(ref_dof, 800) / ref_dof)
        verdicts = [tolerance_check(ref.level * x, check_dof, ref).verdict for x in f]
        # a confident wrong verdict at most as often as the 5 % tests allow
        assert np.mean([v == wrong for v in verdicts]) <= 0.05
    # at the tolerated ratio itself "drifted" comes at the test's level, 5 %
    f = r_star**2 * (rng.chisquare(check_dof, 800) / check_dof) / (rng.chisquare(ref_dof, 800) / ref_dof)
    drifted = np.mean([tolerance_check(ref.level * x, check_dof, ref).verdict == "drifted" for x in f])
    assert abs(drifted - 0.05) < 0.025  # 800 draws: binomial sd 0.8 %
