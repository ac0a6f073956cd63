"""A stated prior for the robot class: the between-session component when one session is all there is.

One calibration session cannot show how much the robot changes from session to session; a
statement for a future session then needs that from elsewhere. A *class prior* states it for a
robot class (a data file with its units and its source: e.g. the spread of full calibrations
of real sessions of robots of that class) in the terms of the between-session model
(:mod:`~robocal_uncertainty.uncertainty.sessions.between`): a standard deviation ``tau`` of the
joint offsets and one of the length scale, each on stated degrees of freedom. A future session
differs from the calibration session by ``2 tau^2``.

With sessions of the robot itself the estimate from them is pooled with the prior as a
scaled-inverse-chi-square prior would be (``tau^2 = (nu_0 tau_0^2 + nu tau_hat^2) / (nu_0 + nu)``
on ``nu_0 + nu`` degrees of freedom): two sessions (one degree of freedom per effect) move a
three-degree-of-freedom prior by a quarter of the way.

Nothing is used by default: without a prior, one session's statement is for that session only
and says so; the prior is named (``calibrate --class-prior ur10``) and recorded in the file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sessions.between import BetweenSessions, identifiable_effects

__all__ = ["SHIPPED_CLASS_PRIORS", "ClassPrior", "load_class_prior", "pooled_with_prior", "prior_between_sessions"]

_DATA = Path(__file__).resolve().parents[2] / "data"
SHIPPED_CLASS_PRIORS = {"ur10": _DATA / "ur10_between_sessions.yaml"}
"""Class priors shipped with the package, by name."""


@dataclass(frozen=True)
class ClassPrior:
    """The between-session spread stated for a robot class.

    Attributes
    ----------
    robot_class : str
    joint_offsets_std : float [rad]
        ``tau`` of each joint offset over sessions.
    length_scale_std : float [1]
        ``tau`` of the links' common length scale over sessions.
    dof : float
        Degrees of freedom of the prior (the sessions it comes from, less one).
    source : str
        Where the values come from (recorded in the calibration file and printed).
    path : str
        The file it was read from.
    """

    robot_class: str
    joint_offsets_std: float
    length_scale_std: float
    dof: float
    source: str
    path: str

    def group_std(self, group: str) -> float:
        """``tau`` of a group of the between-session model (``joint_offsets`` or ``length_scale``)."""
        return self.length_scale_std if group == "length_scale" else self.joint_offsets_std

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (the calibration file's ``between_session.class_prior``)."""
        return {
            "robot_class": self.robot_class,
            "joint_offsets_std_rad": self.joint_offsets_std,
            "length_scale_std": self.length_scale_std,
            "dof": self.dof,
            "source": self.source,
            "file": self.path,
        }


def load_class_prior(name: str | Path) -> ClassPrior:
    """A shipped class prior by name (:data:`SHIPPED_CLASS_PRIORS`) or one from a YAML file.

    Raises
    ------
    ConfigError
        Neither a shipped name nor a readable file; a missing, non-finite or non-positive value;
        no ``source`` (a prior must say where it comes from).
    """
    shipped_path = SHIPPED_CLASS_PRIORS.get(str(name))
    path = Path(name) if shipped_path is None else shipped_path
    label = str(path) if shipped_path is None else f"shipped {name} (robocal_uncertainty/data/{shipped_path.name})"
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        shipped = ", ".join(SHIPPED_CLASS_PRIORS)
        msg = f"class prior {name}: neither a shipped prior ({shipped}) nor a readable YAML file"
        msg += f" ({err.__class__.__name__})"
        raise ConfigError(msg) from err
    if not isinstance(data, dict):
        raise ConfigError(f"class prior {path}: expected a mapping of keys to values")
    values = {}
    for key in ("joint_offsets_std_rad", "length_scale_std", "dof"):
        try:
            value = float(data[key])
        except (KeyError, TypeError, ValueError) as err:
            msg = f"class prior {path}: {key} missing or not a number"
            raise ConfigError(msg) from err
        if not (np.isfinite(value) and value > 0.0):
            msg = f"class prior {path}: {key} must be positive and finite, got {value:g}"
            raise ConfigError(msg)
        values[key] = value
    source = str(data.get("source") or "").strip()
    if not source:
        raise ConfigError(f"class prior {path}: no source (a prior must say where its values come from)")
    return ClassPrior(
        robot_class=str(data.get("robot_class", name)),
        joint_offsets_std=values["joint_offsets_std_rad"],
        length_scale_std=values["length_scale_std"],
        dof=values["dof"],
        source=" ".join(source.split()),
        path=label,
    )


def prior_between_sessions(
    model: RobotModel, campaign: Campaign, prior: ClassPrior, *, retool: bool = True
) -> BetweenSessions:
    """The between-session component of one session from the class prior alone.

    The effects are those the session's campaign can tell apart from a re-registration
    (:func:`~.between.identifiable_effects`), as for several sessions.
    """
    names = identifiable_effects(model, campaign, retool=retool)
    if not names:
        raise ConfigError("no session effect can be told apart from the re-registration on this campaign")
    groups = ["length_scale" if n == "length_scale" else "joint_offsets" for n in names]
    diag = np.array([2.0 * prior.group_std(g) ** 2 for g in groups])
    return BetweenSessions(
        names=names,
        covariance=np.diag(diag),
        group_std={g: prior.group_std(g) for g in dict.fromkeys(groups)},
        group_dof=dict.fromkeys(dict.fromkeys(groups), prior.dof),
        dof=prior.dof,
        n_sessions=1,
        session_effects=np.zeros((0, len(names))),
        session_effects_std=np.zeros((0, len(names))),
        class_prior=prior.to_dict(),
    )


def pooled_with_prior(between: BetweenSessions, prior: ClassPrior) -> BetweenSessions:
    """The sessions' estimate pooled with the class prior, group by group, on the summed degrees of freedom."""
    group_std, group_dof = {}, {}
    diag = np.diag(between.covariance).copy()
    for group, tau in between.group_std.items():
        nu = between.group_dof.get(group, 0.0)
        nu0 = prior.dof
        tau2 = (nu0 * prior.group_std(group) ** 2 + nu * tau**2) / (nu0 + nu)
        group_std[group] = float(np.sqrt(tau2))
        group_dof[group] = float(nu0 + nu)
        cols = [c for c, n in enumerate(between.names) if (n == "length_scale") == (group == "length_scale")]
        diag[cols] = 2.0 * tau2
    return dataclasses.replace(
        between,
        covariance=np.diag(diag),
        group_std=group_std,
        group_dof=group_dof,
        dof=min(group_dof.values()),
        class_prior=prior.to_dict(),
    )
