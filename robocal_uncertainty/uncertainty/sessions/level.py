"""The error level of a check and of the calibration session's own held-out folds, and their test.

The level is the mean square error per component after an ordinary least-squares
re-registration; the calibration's folds give the reference (:func:`check_level`) and a check
is F-tested against it (:func:`level_test`): measured, not stated, because a model-error field's
scale is fixed by one to a few degrees of freedom on real sessions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.session import (
    STATEMENT_TOLERANCE,
    LevelTest,
    ToleranceCheck,
    ValidatedLevel,
)
from robocal_uncertainty.errors import ConfigError, IdentifiabilityError

__all__ = ["FoldLevel", "check_level", "error_level", "level_test", "tolerance_check"]

Array = NDArray[np.float64]


class _LevelOfACheck(Protocol):
    """What :func:`check_level` reads of a fold check (a verification or a :class:`FoldLevel`)."""

    @property
    def level(self) -> float: ...
    @property
    def level_dof(self) -> float: ...
    @property
    def level_trace(self) -> float: ...
    @property
    def level_z(self) -> Array | None: ...
    @property
    def n_poses(self) -> int: ...


@dataclass(frozen=True)
class FoldLevel:
    """A held-out fold's error level (:func:`error_level`) without the rest of a verification.

    Attributes
    ----------
    level : float [m^2]
        Mean square error per kept equation.
    level_dof : float
        ``3 n - k``.
    level_trace : float
        The kept equations ``m_kept``.
    level_z : ndarray, shape (3 n,)
        The standardised components.
    n_poses : int
    """

    level: float
    level_dof: float
    level_trace: float
    level_z: Array | None
    n_poses: int


def error_level(r: Array, a_mat: Array, shape: Array) -> tuple[float, float, Array, float]:
    """``r^T P r / m_kept`` [m^2], its degrees of freedom, the standardised ``P r`` and ``m_kept``.

    ``P`` projects off the re-registration (ordinary least squares: the level does not lean on
    the stated covariance to weight the poses); ``m_kept = 3 n tr(P S P) / tr(S)`` with ``S``
    the stated noise (and calibration-parameter) covariance: the share of the error a
    re-registration of few poses absorbs (the parameter errors are smooth over the poses) is
    taken off, so a fold of 10 poses and a check of 50 measure the same level.
    """
    m = r.size
    if a_mat.shape[1]:
        q_mat, _ = np.linalg.qr(a_mat / np.linalg.norm(a_mat, axis=0))
        rank = int(np.linalg.matrix_rank(a_mat / np.linalg.norm(a_mat, axis=0)))
        q_mat = q_mat[:, :rank]
        proj = np.eye(m) - q_mat @ q_mat.T
    else:
        proj = np.eye(m)
    rp = proj @ r
    # Degrees of freedom 3 n - k (before the dispersion factor). The stated field's own account
    # (the share of a smooth error the projection takes, Satterthwaite's t1^2 / t2) leans on
    # its correlation length, which one campaign hardly fixes (it ran to its bound on the UR10
    # series): it made the level unstable between calibrations of one series and the power of
    # 200-pose checks lower than of 10-pose ones. What correlation and tails the real errors
    # have shows in the scatter of the calibration's fold levels (ValidatedLevel.dispersion).
    dof = float(m - (np.linalg.matrix_rank(a_mat) if a_mat.shape[1] else 0))
    trace = float(np.trace(shape))
    kept = m * float(np.trace(proj @ shape @ proj)) / trace if trace > 0.0 else dof
    level = float(rp @ rp) / kept
    # Standardised components (for the kurtosis): each over its own expected size.
    z = rp / np.sqrt(np.clip(np.diag(proj), 1e-12, None) * max(level, 1e-300))
    return level, dof, np.asarray(z, dtype=np.float64), kept


def level_test(
    level: float, level_dof: float, reference: ValidatedLevel, between: dict[str, object] | None = None
) -> LevelTest:
    """Test a check's error level against the calibration session's validated level.

    ``level / reference.level`` is F distributed with ``(level_dof f, reference.dof f)`` degrees
    of freedom when nothing changed, ``f`` = :attr:`ValidatedLevel.dof_factor` (the dispersion
    the folds showed). With a between-session spread of the level (`between`'s
    ``level_log_std`` over ``level_dof`` degrees of freedom) the statement is for a future
    session: a t test on the log level with Welch-Satterthwaite degrees of freedom.

    Parameters
    ----------
    level : float [m^2]
        The check's mean square error per kept equation.
    level_dof : float
        Its degrees of freedom before the factor (``3 n - k``).
    reference : ValidatedLevel
    between : dict, optional
        The calibration file's ``between_session`` record.
    """
    factor = reference.dof_factor
    nu_c, nu_r = max(level_dof * factor, 1e-3), max(reference.dof * factor, 1e-3)
    t_stat = level / reference.level
    test = "error level"
    p_value = float(stats.f.sf(t_stat, nu_c, nu_r))
    log_std = (between or {}).get("level_log_std")
    if isinstance(log_std, (int, float)) and float(log_std) > 0.0:
        # A future session: its error level varies from session to session (log standard
        # deviation tau over S - 1 degrees of freedom).
        test = "error level, future session"
        parts = np.array([2.0 / nu_c, 2.0 / nu_r, float(log_std) ** 2])
        between_dof_raw = (between or {}).get("level_dof", 1.0)
        between_dof = float(between_dof_raw) if isinstance(between_dof_raw, (int, float)) else 1.0
        dofs = np.array([nu_c, nu_r, max(between_dof, 1.0)])
        welch = float(np.sum(parts) ** 2 / np.sum(parts**2 / dofs))
        p_value = float(stats.t.sf(np.log(t_stat) / np.sqrt(np.sum(parts)), welch))
    interval = (
        float(np.sqrt(t_stat / stats.f.ppf(0.975, nu_c, nu_r))),
        float(np.sqrt(t_stat / stats.f.ppf(0.025, nu_c, nu_r))),
    )
    return LevelTest(test, p_value, float(nu_c), float(nu_r), float(np.sqrt(t_stat)), interval)


def check_level(verifications: Sequence[_LevelOfACheck], *, seed: int = 0, repeats: int = 1) -> ValidatedLevel:
    """Pool held-out fold checks of the calibration session into its :class:`ValidatedLevel`.

    Parameters
    ----------
    verifications : sequence of Verification or FoldLevel
        The fold checks of `repeats` splits (each split holds out every pose once).
    seed : int
        Seed of the splits (recorded).
    repeats : int
        Splits the folds come from.

    The pooled level is the folds' squared residuals over their kept equations (a mean square
    per component [m^2]); its degrees of freedom are one split's summed; the dispersion is the
    fold levels' relative variance about the pooled level over the mean of their normal-theory
    ``2 / nu`` (at least two folds; 1 with one).
    """
    if not verifications:
        raise IdentifiabilityError("no held-out fold to validate the calibration's error level on")
    if repeats < 1 or len(verifications) % repeats:
        msg = f"{len(verifications)} fold checks cannot come from {repeats} splits"
        raise ConfigError(msg)
    num = den = dof = 0.0
    zs = []
    for v in verifications:
        num += v.level * v.level_trace
        den += v.level_trace
        dof += v.level_dof
        if v.level_z is not None:
            zs.append(v.level_z)
    z = np.concatenate(zs) if zs else np.zeros(0)
    kurt = float(np.mean(z**4) / np.mean(z**2) ** 2) if z.size else 3.0
    level = num / den
    levels = np.array([v.level for v in verifications])
    dispersion = None
    if levels.size > 1 and level > 0.0:
        # The fold levels scatter more than their normal-theory 2 / nu when the held-out
        # errors are heavy-tailed, unequal between the axes or correlated within a pose (and
        # by the calibrations of the folds differing): measured, not assumed.
        observed = float(np.sum((levels / level - 1.0) ** 2)) / (levels.size - 1)
        stated = float(np.mean([2.0 / max(v.level_dof, 1e-9) for v in verifications]))
        dispersion = observed / stated
    return ValidatedLevel(
        level=level,
        dof=dof / repeats,
        kurtosis=kurt,
        folds=len(verifications) // repeats,
        poses=int(sum(v.n_poses for v in verifications)) // repeats,
        seed=seed,
        repeats=repeats,
        dispersion=dispersion,
    )


def tolerance_check(
    level: float, level_dof: float, reference: ValidatedLevel, *, reregistered: int = 9
) -> ToleranceCheck:
    """A check's error level against the ratio the statement tolerates (:class:`ToleranceCheck`).

    The level test asks whether the check's errors are larger than the calibration session's;
    a check of 10 poses cannot resolve a ratio of 1.2, so against a session whose errors are
    1.1-1.25x (UR10 series D -> B) its verdict is a coin toss, and against one at 1.3-1.5x it
    often says consistent. This says what the check can stand behind: drifted when the errors
    are significantly beyond the tolerated ratio, consistent when its upper bound is within it,
    inconclusive otherwise, with the check size that could tell.

    Parameters
    ----------
    level : float [m^2]
        The check's mean square error per kept equation.
    level_dof : float
        Its degrees of freedom before the dispersion factor (``3 n - k``).
    reference : ValidatedLevel
    reregistered : int
        Parameters a check re-registers (6 tracker pose + 3 tool point): for `poses_needed`.
    """
    factor = reference.dof_factor
    nu_c, nu_r = max(level_dof * factor, 1e-3), max(reference.dof * factor, 1e-3)
    r_star = float(stats.t.ppf(0.975, nu_r) / stats.norm.ppf(0.5 + (0.95 - STATEMENT_TOLERANCE) / 2.0))
    t_stat = level / reference.level
    p_beyond = float(stats.f.sf(t_stat / r_star**2, nu_c, nu_r))
    upper = float(np.sqrt(t_stat / stats.f.ppf(0.05, nu_c, nu_r)))
    verdict = "drifted" if p_beyond < 0.05 else ("consistent" if upper <= r_star else "inconclusive")
    return ToleranceCheck(verdict, r_star, upper, p_beyond, _poses_needed(r_star, nu_r, factor, reregistered))


def _poses_needed(r_star: float, nu_r: float, factor: float, reregistered: int, most: int = 100_000) -> int | None:
    """Fewest poses whose one-sided 95 % upper ratio bound at ratio 1 is within `r_star` (bisection:
    the bound falls as the check grows); None when even `most` poses do not reach it."""

    def reaches(n: int) -> bool:
        return bool(np.sqrt(1.0 / stats.f.ppf(0.05, (3 * n - reregistered) * factor, nu_r)) <= r_star)

    lo = max(int(np.ceil((reregistered + 1) / 3)), 1)
    if not reaches(most):
        return None
    hi = most
    while lo < hi:
        mid = (lo + hi) // 2
        if reaches(mid):
            hi = mid
        else:
            lo = mid + 1
    return lo
