"""``robocal-uncertainty calibrate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

from robocal_uncertainty.cli._common import campaign_and_robot, parse_lambda
from robocal_uncertainty.cli._evaluation import print_calibration
from robocal_uncertainty.cli._options import add_campaign_args, add_force_arg, add_noise_args, encoder_noise


def register(sub: Any) -> None:
    """Add the ``calibrate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("calibrate", help="identify the parameter errors from a campaign")
    add_campaign_args(p)
    p.add_argument(
        "--lambda",
        dest="lambda_",
        default="auto",
        help="auto (L-curve corner), gcv, or a fixed value (default %(default)s)",
    )
    p.add_argument("--json", help="also write the result to this JSON file (SI units)")
    add_force_arg(p, "the --json file")
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="report an identification that did not converge instead of stopping with an error",
    )
    add_noise_args(p)
    p.add_argument(
        "--sessions",
        nargs="+",
        metavar="CAMPAIGN",
        help="campaigns of the same robot from other sessions (own tracker set-ups): estimate the between-session "
        "component, so that the statement holds for a future session",
    )
    p.add_argument(
        "--class-prior",
        metavar="PRIOR",
        help="a stated between-session spread for the robot class (shipped: ur10; or a YAML file with its units and "
        "source): with one session the statement then holds for a future session; with --sessions it is pooled "
        "with their estimate (default: none, one session's statement is for that session only)",
    )
    p.add_argument(
        "--same-tool",
        action="store_true",
        help="the probe was not remounted between the sessions (default: re-register the tool point on each)",
    )
    p.add_argument(
        "--cross-validation-folds",
        type=int,
        default=5,
        help="with --independent-model-error: model error from this many folds of held-out poses when the model "
        "is inadequate; 0: from the calibration's own residuals (default %(default)s)",
    )
    p.add_argument(
        "--independent-model-error",
        action="store_true",
        help="state the model error as independent from pose to pose (default: a field correlated over the joint "
        "configurations, estimated from the residuals)",
    )
    p.set_defaults(func=run)


def session_lines(state: Any) -> list[str]:
    """What ``calibrate`` prints about the session record it writes."""
    import numpy as np

    me = np.sqrt(np.clip(np.diag(state.model_error_covariance), 0.0, None)) * 1e6
    adequacy = state.extra.get("model_adequacy", {})
    origin = "held-out poses" if adequacy.get("cross_validated") else "calibration residuals"
    me_field = state.model_error_field
    if me_field is not None:
        origin += (
            f"; correlated over the joint configurations: {100 * me_field.correlated_fraction:.0f} % of it, "
            f"length {me_field.length_scale:.2f} rad, {me_field.dof:.0f} degrees of freedom"
        )
    lines = [
        f"session record: {state.n_poses} poses in the {state.frame} frame ({state.frame_id}), "
        f"{len(state.covariance_names)} parameters with covariance, model error u = "
        f"({me[0]:.1f}, {me[1]:.1f}, {me[2]:.1f}) um per axis (base frame, from {origin})"
    ]
    orient = state.orientation_level
    if orient is not None:
        lines.append(
            f"6-DOF: verify also tests a 6-DOF check's orientations against their validated level "
            f"{np.sqrt(orient.level) * 1e3:.3f} mrad per component ({orient.dof * orient.dof_factor:.0f} degrees of "
            f"freedom; {orient.repeats} splits into {orient.folds} folds of the {orient.poses} poses)"
        )
    if state.scope == "session":
        lines.append(
            "statement scope: this session only (one session: a later tracker set-up, probe mounting or drift is "
            "not covered; give --sessions to cover future sessions, or run verify on a check campaign)"
        )
    else:
        between = state.extra.get("between_session", {})
        groups = between.get("group_std", {})
        parts = []
        if "joint_offsets" in groups:
            parts.append(f"joint offsets {np.degrees(groups['joint_offsets']) * 1e3:.2f} mdeg")
        if "length_scale" in groups:
            parts.append(f"length scale {groups['length_scale'] * 1e6:.1f} ppm")
        prior = between.get("class_prior")
        origin = f"from {between.get('n_sessions')} sessions"
        if prior is not None:
            origin = (
                "from the class prior alone"
                if between.get("n_sessions") == 1
                else f"from {between.get('n_sessions')} sessions pooled with the class prior"
            )
        lines.append(
            f"statement scope: future sessions (between-session component {origin}, "
            f"{between.get('dof', state.between_session_dof):.0f}+ degrees of freedom: {', '.join(parts)} per session)"
        )
        if prior is not None:
            lines.append(f"class prior {prior['file']}: {prior['robot_class']}; source: {prior['source']}")
        ratios = between.get("level_ratios") or []
        if between.get("level_log_std") is not None and ratios:
            p_values = between.get("level_p_values") or []
            shown = ", ".join(f"{r:.2f}x (p = {p:.2g})" for r, p in zip(ratios, p_values))
            lines.append(
                f"error level of the later sessions against this calibration's validated level: {shown}; "
                f"between-session spread of the level: log sd {between['level_log_std']:.2f} on "
                f"{between.get('level_dof', 0):.0f} degree(s) of freedom"
                + (
                    " (too few sessions to fix it: verify's test of a future session is wide)"
                    if len(ratios) < 3
                    else ""
                )
            )
    return lines


def run(args: argparse.Namespace) -> int:

    from robocal_uncertainty.app.campaign_checks import check_campaign_joints
    from robocal_uncertainty.app.verification import calibrate_session
    from robocal_uncertainty.cli._common import read_campaign_checked
    from robocal_uncertainty.core import TrackerNoise
    from robocal_uncertainty.core.calibration_file import write_calibration
    from robocal_uncertainty.errors import ConfigError

    if args.cross_validation_folds < 0 or args.cross_validation_folds == 1:
        msg = f"--cross-validation-folds must be 0 or at least 2, got {args.cross_validation_folds}"
        raise ConfigError(msg)
    prior = None
    if args.class_prior:
        from pathlib import Path

        from robocal_uncertainty.uncertainty.sessions.class_prior import SHIPPED_CLASS_PRIORS, load_class_prior

        # A shipped prior belongs to one shipped robot: another shipped robot (named, not a file
        # the user vouches for) would get a statement from a class it is not in.
        robot_is_shipped_name = Path(str(args.robot)).suffix == "" and "/" not in str(args.robot)
        if args.class_prior in SHIPPED_CLASS_PRIORS and robot_is_shipped_name and args.robot != args.class_prior:
            msg = (
                f"--class-prior {args.class_prior} is the between-session prior of the {args.class_prior} class, "
                f"not of --robot {args.robot}: give a prior file for that robot's class"
            )
            raise ConfigError(msg)
        prior = load_class_prior(args.class_prior)
    campaign, model = campaign_and_robot(args)
    later = []
    for path in args.sessions or ():
        session = read_campaign_checked(args, path)
        check_campaign_joints(model, session, path)
        later.append(session)
    calibration = calibrate_session(
        model,
        campaign,
        tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
        encoder_noise=encoder_noise(args),
        lambda_=parse_lambda(args.lambda_),
        accept_unconverged=args.accept_unconverged,
        campaign_name=str(args.campaign),
        cross_validation_folds=args.cross_validation_folds,
        correlated_model_error=not args.independent_model_error,
        later_sessions=later,
        retool=not args.same_tool,
        class_prior=prior,
    )
    print_calibration(calibration.result)
    for warning in calibration.warnings:
        print(f"warning: {warning}")
    if calibration.state is not None:
        for line in session_lines(calibration.state):
            print(line)
    if args.json:
        write_calibration(args.json, calibration.result, robot=str(args.robot), session=calibration.state)
        print(f"wrote {args.json}")
    return 0
