"""Between-session reproducibility: what changes from one measurement session to the next.

A calibration holds for the session it was measured in. In a later session the tracker
stands elsewhere and the probe may be remounted (both are re-registered on the new session's
measurements), but the robot itself also moves a little: encoder zeros drift, re-homing
shifts joint offsets, a warmer workshop stretches the links. Those *session effects* are what
a re-registration cannot absorb. From two or more sessions of the same robot:

1. the first session's calibration is the reference;
2. every other session is re-registered (tracker pose and tool point) and its session
   effects (joint offsets ``jointN.theta``, the ``length_scale`` of the links) are estimated
   by one GLS step against the reference, with their covariance ``V_s`` (noise, model error
   and calibration uncertainty; :func:`~.verification.verify_session`);
3. a random-effects model ``e_s = u_s - u_1 + eps_s``, ``u ~ N(0, tau_g^2)`` per group (joint
   offsets share one variance, the length scale has its own), is fitted by moments:
   ``2 tau_g^2 = max(0, sum_s sum_{j in g} (e_sj^2 - V_s,jj) / ((S - 1) |g|))`` with
   ``(S - 1) |g|`` degrees of freedom.

A future session differs from the reference by ``u_new - u_1``: covariance ``2 tau_g^2``. That
is the between-session covariance written to the calibration file (``between_session``), used
by ``verify`` and by the Monte Carlo source ``between_session`` (which adds it to every
prediction), so a statement in the robot base frame holds for a future session after its
tracker and probe are re-registered. Effects a re-registration absorbs (the first joint's
offset with the tracker's yaw, the last one's with a remounted tool off its axis) are left out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.calibration_file import read_calibration, read_session_state
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import LENGTH_SCALE, SessionState, Verification, effect_jacobian
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sessions.verification import verify_session

__all__ = [
    "BetweenSessions",
    "between_sessions_from_file",
    "estimate_between_sessions",
    "identifiable_effects",
    "with_between_sessions",
]

Array = NDArray[np.float64]
_RCOND = 1e-6


@dataclass(frozen=True, eq=False)
class BetweenSessions:
    """Between-session component estimated from several sessions.

    Attributes
    ----------
    names : tuple of str, length k
        Session effects (joint offsets [rad], ``length_scale`` [1]).
    covariance : ndarray, shape (k, k)
        Covariance of a future session's effects relative to the reference calibration
        (``2 tau_g^2`` on the diagonal).
    group_std : dict
        ``tau_g`` per group (``joint_offsets`` [rad], ``length_scale`` [1]).
    group_dof : dict
        Degrees of freedom of each group's estimate.
    dof : float
        Smallest of them (what the check's null distribution uses).
    n_sessions : int
    session_effects : ndarray, shape (n_sessions - 1, k)
        Effects of every later session relative to the reference.
    session_effects_std : ndarray, shape (n_sessions - 1, k)
    level_ratios : ndarray, shape (n_sessions - 1,)
        Every later session's error level (mean square per component after re-registering
        tracker and tool on all its poses, ordinary least squares) over the reference
        calibration's validated level: what the parameter effects leave (empty without a
        validated level).
    level_p_values : ndarray, shape (n_sessions - 1,)
        F test of each ratio (small: the session disagrees beyond the stated uncertainty).
    level_log_std : float or None
        Between-session standard deviation of the log error level: the sample standard
        deviation of ``log`` of ``(1, ratios...)`` less its estimation noise (``2 / nu`` per
        level), at least the spread that the F tests call significant. None: no validated level.
    level_dof : float
        Its degrees of freedom (``n_sessions - 1``).
    class_prior : dict or None
        The stated prior for the robot class the component comes from (one session) or is
        pooled with (several; :mod:`~.class_prior`); None: the sessions alone.
    """

    names: tuple[str, ...]
    covariance: Array
    group_std: dict[str, float]
    group_dof: dict[str, float]
    dof: float
    n_sessions: int
    session_effects: Array
    session_effects_std: Array
    level_ratios: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    level_p_values: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    level_log_std: float | None = None
    level_dof: float = 0.0
    warnings: tuple[str, ...] = ()
    class_prior: dict[str, object] | None = None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary (the calibration file's ``between_session``)."""
        if self.class_prior is None:
            model = "random effects per group, moments; future session relative to the reference"
        elif self.n_sessions == 1:
            model = "class prior alone (one session); future session relative to the reference"
        else:
            model = "random effects per group, moments, pooled with the class prior; future session relative to "
            model += "the reference"
        return {
            "model": model,
            "class_prior": self.class_prior,
            "n_sessions": self.n_sessions,
            "group_std": dict(self.group_std),
            "group_dof": dict(self.group_dof),
            "dof": self.dof,
            "session_effects": self.session_effects.tolist(),
            "session_effects_std": self.session_effects_std.tolist(),
            "level_ratios": self.level_ratios.tolist(),
            "level_p_values": self.level_p_values.tolist(),
            "level_log_std": self.level_log_std,
            "level_dof": self.level_dof,
        }


def _group(name: str) -> str:
    return "length_scale" if name == LENGTH_SCALE else "joint_offsets"


def identifiable_effects(
    model: RobotModel, campaign: Campaign, candidates: Sequence[str] | None = None, *, retool: bool = True
) -> tuple[str, ...]:
    """The session effects a campaign can tell apart from its re-registration.

    Columns are added in order (joint offsets, then the length scale) while they raise the
    rank of the column-scaled Jacobian of ``[tracker pose, tool point, effects]``.
    """
    layout = model.layout
    names = list(candidates) if candidates is not None else [f"{j}.theta" for j in _joint_prefixes(model)]
    if candidates is None:
        names.append(LENGTH_SCALE)
    p = model.parameter_vector()
    q = campaign.reorder_joints(model.joint_names).joint_positions
    _, jac = forward_points_and_jacobian(layout, p, q)
    free = [layout.index(n) for n in ("base.x", "base.y", "base.z", "base.roll", "base.pitch", "base.yaw")]
    if retool:
        free += [layout.index(n) for n in ("tool.x", "tool.y", "tool.z")]
    cols = jac[:, :, free].reshape(-1, len(free))
    g = effect_jacobian(layout, p, q, tuple(names)).reshape(cols.shape[0], len(names))
    kept: list[str] = []
    current = cols / np.linalg.norm(cols, axis=0)
    rank = int(np.linalg.matrix_rank(current, tol=None))
    for c, name in enumerate(names):
        column = g[:, c : c + 1]
        norm = float(np.linalg.norm(column))
        if norm == 0.0:
            continue
        trial = np.concatenate((current, column / norm), axis=1)
        s = np.linalg.svd(trial, compute_uv=False)
        if s[-1] > _RCOND * s[0] and int(np.sum(s > _RCOND * s[0])) > rank:
            current, rank = trial, rank + 1
            kept.append(name)
    return tuple(kept)


def _joint_prefixes(model: RobotModel) -> list[str]:
    layout = model.layout
    out = []
    for idx in layout.joint_slices():
        name = layout.names[idx["theta"]]
        out.append(name.rsplit(".", 1)[0])
    return out


def estimate_between_sessions(
    model: RobotModel,
    state: SessionState,
    sessions: Sequence[Campaign],
    *,
    effects: Sequence[str] | None = None,
    retool: bool = True,
    null_trials: int = 200,
    reference_campaign: Campaign | None = None,
    significance: float = 0.05,
) -> BetweenSessions:
    """Estimate the between-session covariance from sessions after the reference.

    Parameters
    ----------
    model : RobotModel
        The calibrated model of the reference session.
    state : SessionState
        The reference session's record.
    sessions : sequence of Campaign
        One campaign per later session (each in its own tracker frame), >= 1.
    effects : sequence of str, optional
        Session effects; by default every joint offset and the length scale that the first
        later session can tell apart from its re-registration.
    retool : bool
        Re-register the tool point on every session (the probe was remounted).
    null_trials : int
        Draws of each session's check statistic (only its effects are used here).
    reference_campaign : Campaign, optional
        The reference calibration's campaign: a later session that repeats it is refused.
    significance : float
        Level of the per-session F tests of the error level.

    Raises
    ------
    ConfigError
        No later session, no identifiable effect, or a session given twice (the same poses
        and measurements, whatever its name): a session counts once.

    Notes
    -----
    Two sessions that disagree beyond their stated uncertainty (an F test of the level says
    so) never give a zero component: when the moments of the parameter effects come out
    non-positive (the effects' stated covariance, a model-error field over the poses, holds
    more than they scatter), the effects' raw mean square is used, and the error level's
    between-session spread is at least the log of the significant ratios.
    """
    names = _session_effect_names(model, sessions, effects, retool, reference_campaign)
    checks = [
        verify_session(model, state, campaign, retool=retool, effects=names, null_trials=null_trials)
        for campaign in sessions
    ]
    values = []
    stds = []
    variances = []
    for check in checks:
        assert check.effects is not None and check.effects_covariance is not None
        values.append(check.effects)
        variances.append(np.diag(check.effects_covariance))
        stds.append(np.sqrt(np.clip(np.diag(check.effects_covariance), 0.0, None)))
    e = np.asarray(values)
    ratios, p_values, log_std, disagree = _level_spread(state, checks, significance)
    diag, group_std, group_dof = _group_components(names, e, np.asarray(variances), disagree)
    return BetweenSessions(
        names=names,
        covariance=np.diag(diag),
        group_std=group_std,
        group_dof=group_dof,
        dof=min(group_dof.values()),
        n_sessions=len(sessions) + 1,
        session_effects=e,
        session_effects_std=np.asarray(stds),
        level_ratios=ratios,
        level_p_values=p_values,
        level_log_std=log_std,
        level_dof=float(len(sessions)),
    )


def _session_effect_names(
    model: RobotModel,
    sessions: Sequence[Campaign],
    effects: Sequence[str] | None,
    retool: bool,
    reference_campaign: Campaign | None,
) -> tuple[str, ...]:
    """The effects to estimate, after refusing too few sessions and a session given twice."""
    if len(sessions) < 1:
        raise ConfigError("a between-session component needs at least two sessions (the reference and one more)")
    labels = [f"later session {k + 1}" for k in range(len(sessions))]
    if reference_campaign is not None:
        _refuse_repeats([reference_campaign, *sessions], ["the reference calibration's campaign", *labels])
    else:
        _refuse_repeats(list(sessions), labels)
    names = tuple(effects) if effects is not None else identifiable_effects(model, sessions[0], retool=retool)
    if not names:
        raise ConfigError("no session effect can be told apart from the re-registration on these sessions")
    return names


def _group_components(
    names: tuple[str, ...], e: Array, v: Array, disagree: bool
) -> tuple[Array, dict[str, float], dict[str, float]]:
    """Per effect ``2 tau_g^2`` of its group (moments), with each group's ``tau_g`` and dof."""
    group_std: dict[str, float] = {}
    group_dof: dict[str, float] = {}
    diag = np.zeros(len(names))
    for group in dict.fromkeys(_group(n) for n in names):
        cols = [c for c, n in enumerate(names) if _group(n) == group]
        count = e.shape[0] * len(cols)
        two_tau2 = max(float(np.sum(e[:, cols] ** 2 - v[:, cols])) / count, 0.0)
        if two_tau2 == 0.0 and disagree:
            two_tau2 = float(np.sum(e[:, cols] ** 2)) / count
        group_std[group] = float(np.sqrt(two_tau2 / 2.0))
        group_dof[group] = float(count)
        diag[cols] = two_tau2
    return diag, group_std, group_dof


def _fingerprint(campaign: Campaign) -> set[bytes]:
    """One key per pose: its joint positions and measured point, rounded to 1 nm / 1 nrad."""
    y = campaign.measurement.positions(campaign.points)
    rows = campaign.joint_positions if y is None else np.concatenate((campaign.joint_positions, y), axis=1)
    keys = np.round(np.asarray(rows, dtype=np.float64) * 1e9).astype(np.int64)
    return {row.tobytes() for row in keys}


def _refuse_repeats(campaigns: Sequence[Campaign], labels: Sequence[str]) -> None:
    """A session given twice (half or more of its poses with the same joints and measurements,
    under any name) is refused: it would count as a second session that agrees perfectly."""
    prints = [_fingerprint(c) for c in campaigns]
    for i in range(len(prints)):
        for j in range(i):
            shared = len(prints[i] & prints[j])
            if shared and shared >= 0.5 * min(len(prints[i]), len(prints[j])):
                msg = (
                    f"{labels[i]} repeats {labels[j]} ({shared} poses with the same joints and measurements): "
                    "a session counts once; give each measurement session one campaign"
                )
                raise ConfigError(msg)


def _level_spread(
    state: SessionState, checks: Sequence[Verification], significance: float
) -> tuple[Array, Array, float | None, bool]:
    """Error-level ratios of the later sessions against the reference's validated level."""
    from scipy import stats

    ref = state.validated_level
    if ref is None:
        return np.zeros(0), np.zeros(0), None, False
    ratios, p_values, noise = [], [], [2.0 / (ref.dof * ref.dof_factor)]
    for v in checks:
        nu = v.level_dof * ref.dof_factor
        t = v.level / ref.level
        ratios.append(float(np.sqrt(t)))
        p_values.append(float(stats.f.sf(t, nu, ref.dof * ref.dof_factor)))
        noise.append(2.0 / nu)
    logs = np.log(np.concatenate(([1.0], np.asarray(ratios) ** 2)))
    sample_var = float(np.var(logs, ddof=1))
    disagree = bool(np.any(np.asarray(p_values) < significance))
    var = max(sample_var - float(np.mean(noise)), 0.0)
    if disagree:
        # Sessions the F test separates: the spread is at least what their significant ratios show.
        significant = np.log(np.asarray(ratios)[np.asarray(p_values) < significance] ** 2)
        var = max(var, float(np.mean(significant**2)) / 2.0)
    return np.asarray(ratios), np.asarray(p_values), float(np.sqrt(var)), disagree


def between_sessions_from_file(path: str | Path) -> BetweenSessions:
    """The between-session component of a calibration file (``calibrate --sessions``).

    Raises
    ------
    ConfigError
        Not a calibration, or one without a between-session component.
    """
    where = f"calibration {path}"
    state = read_session_state(read_calibration(path), where=where)
    if state is None or state.between_session_covariance is None or not state.between_session_names:
        msg = f"{where} has no between-session component: calibrate it with --sessions (campaigns of other sessions)"
        raise ConfigError(msg)
    summary = state.extra.get("between_session", {})
    assert isinstance(summary, dict)
    k = len(state.between_session_names)
    return BetweenSessions(
        names=state.between_session_names,
        covariance=state.between_session_covariance,
        group_std={str(a): float(b) for a, b in dict(summary.get("group_std", {})).items()},
        group_dof={str(a): float(b) for a, b in dict(summary.get("group_dof", {})).items()},
        dof=float(state.between_session_dof if state.between_session_dof is not None else np.inf),
        n_sessions=int(summary.get("n_sessions", 0)),
        session_effects=np.asarray(summary.get("session_effects", np.zeros((0, k))), dtype=np.float64),
        session_effects_std=np.asarray(summary.get("session_effects_std", np.zeros((0, k))), dtype=np.float64),
        class_prior=summary.get("class_prior"),
    )


def with_between_sessions(state: SessionState, between: BetweenSessions) -> SessionState:
    """The session record with the between-session component: its statements hold for future sessions."""
    extra = dict(state.extra)
    extra["between_session"] = between.to_dict()
    return dataclasses.replace(
        state,
        between_session_names=between.names,
        between_session_covariance=between.covariance,
        between_session_dof=between.dof,
        scope="future sessions",
        extra=extra,
    )
