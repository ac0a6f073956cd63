"""Views of a check measurement (``verify``): console lines, JSON, Markdown and a plot.

All numbers come from :class:`~robocal_uncertainty.core.session.Verification`; lengths are
shown in mm (moves) or µm (per-pose errors), angles in mrad; the JSON keeps SI units.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from robocal_uncertainty.core.session import LENGTH_SCALE, ToleranceCheck, Verification

__all__ = [
    "VERIFICATION_FORMAT",
    "orientation_lines",
    "plot_verification",
    "tolerance_line",
    "verification_lines",
    "verification_markdown",
    "verification_summary",
    "verification_to_dict",
    "write_verification_report",
]

VERIFICATION_FORMAT = "robocal_uncertainty/verification/1"
_AXES = ("x", "y", "z")


def _list(values: NDArray[np.float64] | None) -> Any:
    return None if values is None else np.asarray(values, dtype=np.float64).tolist()


def _effect_text(name: str, value: float, std: float) -> str:
    if name == LENGTH_SCALE:
        return f"{name} {value * 1e6:+.1f} ± {std * 1e6:.1f} ppm"
    return f"{name} {np.degrees(value) * 1e3:+.2f} ± {np.degrees(std) * 1e3:.2f} mdeg"


def verification_summary(result: Verification) -> str:
    """One line: the verdict with its p-value and how far the tracker (and tool point) moved.

    What the calibration node's ``~/verify`` answers and logs; the full lines are
    :func:`verification_lines`.
    """
    positions_ok = result.p_value >= result.significance
    if result.consistent or positions_ok:
        word = "consistent" if result.consistent else "positions consistent"
        head = f"{word} (p = {result.p_value:.3g} >= {result.significance:g}"
    else:
        head = (
            f"drifted by about {result.excess_std * 1e3:.3g} mm per axis beyond "
            + ("the stated uncertainty " if result.test == "chi-square" else "the calibration's validated error level ")
            + f"(p = {result.p_value:.3g} < {result.significance:g}"
        )
    parts = [f"{head}, chi2 = {result.chi2:.3g} on {result.dof} degrees of freedom, {result.n_poses} poses)"]
    if result.error_ratio is not None and result.error_ratio_interval is not None:
        lo, hi = result.error_ratio_interval
        parts.append(f"errors {result.error_ratio:.2f}x the calibration session's (95 % interval {lo:.2f}-{hi:.2f})")
    o = result.orientation
    if o is not None:
        t = o.level_test
        parts.append(
            f"orientations {'consistent' if o.consistent else 'drifted'}: errors {t.ratio:.2f}x the calibration "
            f"session's (p = {t.p_value:.3g} {'>=' if o.consistent else '<'} {o.significance:g})"
        )
    move = result.move
    alike = inseparable(result)
    if alike:
        parts.append(f"tracker move and tool point cannot be separated by this check ({', '.join(alike)} act alike)")
    elif move is not None:
        parts.append(
            f"tracker moved {move.distance * 1e3:.3f} ± {move.distance_std * 1e3:.3f} mm and turned "
            f"{move.angle * 1e3:.3f} ± {move.angle_std * 1e3:.3f} mrad"
        )
    if result.tool_change is not None and not alike:
        parts.append(f"tool point moved {float(np.linalg.norm(result.tool_change)) * 1e3:.3f} mm")
    if not result.consistent:
        parts.append("re-calibrate")
    return "; ".join(parts)


INSEPARABLE_VIF = 1000.0
"""Variance inflation factor above which a re-registered parameter is reported as not separable
from the others: its standard uncertainty is then more than 30 times what it would be if the
check determined it alone (honest checks of the README's shop-floor example: at most 10; a
probe on joint 6's axis checked by poses that barely turn it: about 10^6)."""


def inseparable(result: Verification) -> tuple[str, ...]:
    """Re-registered parameters the check cannot tell apart from the others (a combination of
    them is determined, not each): variance inflation factor above :data:`INSEPARABLE_VIF`."""
    cov = np.asarray(result.registration_covariance, dtype=np.float64)
    if cov.size == 0:
        return ()
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if not np.isfinite(std).all() or (std == 0.0).any():
        return tuple(result.reregistered)
    vif = np.diag(np.linalg.pinv(cov / np.outer(std, std)))
    return tuple(n for n, v in zip(result.reregistered, vif) if not v <= INSEPARABLE_VIF)


def _inseparable_line(names: tuple[str, ...]) -> str:
    return (
        f"tracker move and tool point cannot be separated by this check: {', '.join(names)} act alike (e.g. the "
        "probe length and the tracker distance along the probe axis), so no value is stated for them. "
        "Turn the probe through more orientations in the check, or "
        "verify without --retool"
    )


def tolerance_line(check: ToleranceCheck) -> str:
    """The check against what the statement tolerates: consistent, drifted or inconclusive."""
    head = (
        f"against the statement's tolerance (its 95 % region holding at least 91 % of the points: errors up to "
        f"{check.tolerated_ratio:.2f}x): "
    )
    need = (
        f"a check shows errors within it from {check.poses_needed} poses on (errors at the calibration's level)"
        if check.poses_needed is not None
        else "no check size can show errors within it: the validated level itself is too uncertain"
    )
    if check.verdict == "inconclusive":
        return (
            head + f"inconclusive: this check's errors may be up to {check.upper_ratio:.2f}x (one-sided 95 %) "
            f"and are not clearly beyond {check.tolerated_ratio:.2f}x (p = {check.p_beyond:.3g}); {need}"
        )
    if check.verdict == "drifted":
        return head + f"drifted: the errors are beyond it (p = {check.p_beyond:.3g} < 0.05)"
    return head + f"consistent: the errors are within it (at most {check.upper_ratio:.2f}x, one-sided 95 %)"


def orientation_lines(result: Verification) -> list[str]:
    """A 6-DOF check's orientation half: its RMS and its tolerance line (empty for points)."""
    o = result.orientation
    if o is None:
        return []
    return [
        f"orientations: RMS {o.rms * 1e3:.3f} mrad after re-registering {', '.join(o.reregistered)}; "
        f"errors {o.level_test.ratio:.2f}x the calibration session's (p = {o.level_test.p_value:.3g})",
        "orientations " + tolerance_line(o.tolerance),
    ]


def verification_lines(result: Verification, *, scope: str = "session") -> list[str]:
    """What ``verify`` prints: the verdict, the re-registration, the test and the worst poses."""
    lines = [result.verdict]
    if result.tolerance is not None:
        lines.append(tolerance_line(result.tolerance))
    lines.extend(orientation_lines(result))
    move = result.move
    alike = inseparable(result)
    if alike:
        lines.append(_inseparable_line(alike))
        if move is not None and not {"base.x", "base.y", "base.z"} & set(alike):
            lines.append(
                f"tracker turned {move.angle * 1e3:.3f} ± {move.angle_std * 1e3:.3f} mrad since the calibration session"
            )
    elif move is not None:
        t, ts = move.translation * 1e3, move.translation_std * 1e3
        lines.append(
            f"tracker moved {move.distance * 1e3:.3f} ± {move.distance_std * 1e3:.3f} mm "
            f"(x {t[0]:+.3f} ± {ts[0]:.3f}, y {t[1]:+.3f} ± {ts[1]:.3f}, z {t[2]:+.3f} ± {ts[2]:.3f} mm, "
            "robot base frame) "
            f"and turned {move.angle * 1e3:.3f} ± {move.angle_std * 1e3:.3f} mrad since the calibration session"
        )
    if result.tool_change is not None and result.tool_change_std is not None and not alike:
        d, s = result.tool_change * 1e3, result.tool_change_std * 1e3
        lines.append(
            f"tool point re-registered: changed by ({d[0]:+.3f} ± {s[0]:.3f}, {d[1]:+.3f} ± {s[1]:.3f}, "
            f"{d[2]:+.3f} ± {s[2]:.3f}) mm"
        )
    lines.append(
        f"{result.n_poses} check poses, {3 * result.n_poses} equations, {len(result.reregistered)} re-registered "
        f"({result.dof} degrees of freedom left); RMS error after re-registration {result.rms_error * 1e3:.3f} mm; "
        f"chi2 = {result.chi2:.2f}, p = {result.p_value_statement:.3g} against the statement alone (Monte Carlo "
        f"null, {result.null_trials} draws, seed {result.seed}; chi-square approximation p = {result.p_value_chi2:.3g})"
        + (
            ""
            if result.test == "chi-square"
            else f"; the verdict is the {result.test} test's (p = {result.p_value:.3g})"
        )
    )
    me = result.model_error_std * 1e6
    lines.append(
        f"stated per pose: model error u = ({me[0]:.1f}, {me[1]:.1f}, {me[2]:.1f}) um (base frame"
        + (
            ""
            if result.model_error_length_scale is None
            else f"; correlated between the poses, length {result.model_error_length_scale:.2f} rad"
        )
        + f") plus tracker, encoder and calibration uncertainty; statement valid for: {scope}"
    )
    worst = np.argsort(-result.pose_chi2)[: min(3, result.n_poses)]
    parts = []
    for i in worst:
        z = result.normalised[i]
        parts.append(f"pose {i}: |z| = ({abs(z[0]):.2f}, {abs(z[1]):.2f}, {abs(z[2]):.2f})")
    lines.append("largest normalised errors: " + "; ".join(parts))
    if result.effects is not None and result.effects_covariance is not None:
        std = np.sqrt(np.clip(np.diag(result.effects_covariance), 0.0, None))
        text = ", ".join(
            _effect_text(n, float(v), float(s)) for n, v, s in zip(result.effect_names, result.effects, std)
        )
        lines.append(f"session effects since the calibration: {text}")
    lines.extend(f"warning: {w}" for w in result.warnings)
    return lines


def verification_to_dict(
    result: Verification, *, calibration: str = "", check_campaign: str = "", robot: str = "", scope: str = "session"
) -> dict[str, Any]:
    """JSON-ready report (SI units)."""
    move = result.move
    return {
        "format": VERIFICATION_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "robot": robot,
        "calibration": calibration,
        "check_campaign": check_campaign,
        "scope": scope,
        "consistent": result.consistent,
        "verdict": result.verdict,
        "test": {
            "statistic": "generalised least-squares chi2 after re-registration"
            if result.test == "chi-square"
            else "error level against the calibration's validated level (F test; chi2 for reference)",
            "chi2": result.chi2,
            "dof": result.dof,
            "p_value": result.p_value,
            "p_value_chi2_approximation": result.p_value_chi2,
            "p_value_chi2_against_statement": result.p_value_statement,
            "verdict_test": result.test,
            "significance": result.significance,
            "null_trials": result.null_trials,
            "seed": result.seed,
            "excess_std_m": result.excess_std,
        },
        "error_level": {
            "test": result.test,
            "statement": "mean square error per component after re-registration, relative to the "
            "calibration session's own held-out poses (F test)",
            "level_m2": result.level,
            "level_dof": result.level_dof,
            "error_ratio": result.error_ratio,
            "error_ratio_interval_95": None
            if result.error_ratio_interval is None
            else list(result.error_ratio_interval),
            "tolerance": None if result.tolerance is None else result.tolerance.to_dict(),
        },
        "orientation": None if result.orientation is None else result.orientation.to_dict(),
        "duplicate_poses_dropped": result.duplicates,
        "n_poses": result.n_poses,
        "rms_error_m": result.rms_error,
        "reregistered": list(result.reregistered),
        "inseparable": list(inseparable(result)),
        "registration": _list(result.registration),
        "registration_covariance": _list(result.registration_covariance),
        "tracker_move": None
        if move is None
        else {
            "translation_m": _list(move.translation),
            "translation_std_m": _list(move.translation_std),
            "distance_m": move.distance,
            "distance_std_m": move.distance_std,
            "rotation_rad": _list(move.rotation),
            "rotation_std_rad": _list(move.rotation_std),
            "angle_rad": move.angle,
            "angle_std_rad": move.angle_std,
        },
        "tool_change_m": _list(result.tool_change),
        "tool_change_std_m": _list(result.tool_change_std),
        "poses": {
            "residuals_m": _list(result.residuals),
            "stated_std_m": _list(result.stated_std),
            "normalised": _list(result.normalised),
            "pose_chi2": _list(result.pose_chi2),
        },
        "model_error_std_m": _list(result.model_error_std),
        "model_error_length_scale_rad": result.model_error_length_scale,
        "session_effects": None
        if result.effects is None
        else {
            "names": list(result.effect_names),
            "values": _list(result.effects),
            "covariance": _list(result.effects_covariance),
        },
        "warnings": list(result.warnings),
    }


def verification_markdown(result: Verification, *, calibration: str, check_campaign: str, scope: str) -> str:
    """The report as Markdown."""
    lines = [
        "# Check measurement",
        "",
        f"Calibration `{calibration}`, check campaign `{check_campaign}`.",
        "",
        f"**{'Consistent' if result.consistent else 'Drifted'}.** {result.verdict}",
        "",
        *([] if result.tolerance is None else [tolerance_line(result.tolerance), ""]),
        *(f"{line}\n" for line in orientation_lines(result)),
        "## Re-registration",
        "",
    ]
    move = result.move
    alike = inseparable(result)
    if alike:
        lines += [_inseparable_line(alike) + ".", ""]
    elif move is not None:
        lines += [
            "| quantity | value | standard uncertainty |",
            "| --- | --- | --- |",
            f"| tracker move | {move.distance * 1e3:.3f} mm | {move.distance_std * 1e3:.3f} mm |",
        ]
        for k, axis in enumerate(_AXES):
            value, std = move.translation[k] * 1e3, move.translation_std[k] * 1e3
            lines.append(f"| move {axis} (base frame) | {value:+.3f} mm | {std:.3f} mm |")
        lines.append(f"| tracker rotation | {move.angle * 1e3:.3f} mrad | {move.angle_std * 1e3:.3f} mrad |")
        if result.tool_change is not None and result.tool_change_std is not None:
            for k, axis in enumerate(_AXES):
                lines.append(
                    f"| tool change {axis} | {result.tool_change[k] * 1e3:+.3f} mm | "
                    f"{result.tool_change_std[k] * 1e3:.3f} mm |"
                )
        lines.append("")
    else:
        lines += ["Base-frame check: nothing re-registered but what was asked.", ""]
    lines += [
        "## Test",
        "",
        f"- poses: {result.n_poses}; re-registered parameters: {len(result.reregistered)}; "
        f"degrees of freedom: {result.dof}",
        f"- chi2 = {result.chi2:.3f}; p = {result.p_value_statement:.4g} against the statement alone (Monte Carlo "
        f"null distribution, {result.null_trials} draws, seed {result.seed}); chi-square approximation "
        f"p = {result.p_value_chi2:.4g}; verdict from the {result.test} test, p = {result.p_value:.4g}",
        f"- significance level (false-alarm rate when nothing changed): {result.significance:g}",
        f"- extra error per axis needed to explain the check: {result.excess_std * 1e3:.4g} mm",
        f"- statement valid for: {scope}",
        "",
        "## Per pose",
        "",
        "| pose | error x [µm] | error y [µm] | error z [µm] | z_x | z_y | z_z |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for i in range(result.n_poses):
        r = result.residuals[i] * 1e6
        z = result.normalised[i]
        lines.append(f"| {i} | {r[0]:.1f} | {r[1]:.1f} | {r[2]:.1f} | {z[0]:+.2f} | {z[1]:+.2f} | {z[2]:+.2f} |")
    if result.effects is not None and result.effects_covariance is not None:
        std = np.sqrt(np.clip(np.diag(result.effects_covariance), 0.0, None))
        lines += ["", "## Session effects since the calibration", ""]
        lines += [
            f"- {_effect_text(n, float(v), float(s))}" for n, v, s in zip(result.effect_names, result.effects, std)
        ]
    if result.warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in result.warnings]
    return "\n".join(lines) + "\n"


def plot_verification(result: Verification, path: str | Path) -> Path:
    """Normalised error of every check pose and axis against the ±1.96 band; writes a PNG."""
    fig = Figure(figsize=(7.0, 3.6), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.1, 0.16, 0.86, 0.72))
    poses = np.arange(result.n_poses)
    for k, (axis, marker) in enumerate(zip(_AXES, ("o", "s", "^"))):
        ax.plot(poses + (k - 1) * 0.15, result.normalised[:, k], marker, ls="none", label=axis)
    ax.axhspan(-1.96, 1.96, color="0.9", zorder=0, label="95 % band")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("check pose")
    ax.set_ylabel("normalised error z")
    ax.set_title(("consistent" if result.consistent else "drifted") + f" (p = {result.p_value:.3g})")
    ax.legend(loc="upper right", ncol=4, fontsize="small")
    out = Path(path)
    fig.savefig(out)
    return out


def write_verification_report(
    result: Verification, out_dir: str | Path, *, calibration: str, check_campaign: str, robot: str, scope: str
) -> list[Path]:
    """Write ``verify.json``, ``verify.md`` and ``verify.png`` into `out_dir` (created)."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    data = verification_to_dict(
        result, calibration=calibration, check_campaign=check_campaign, robot=robot, scope=scope
    )
    paths = [directory / "verify.json", directory / "verify.md", directory / "verify.png"]
    paths[0].write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    paths[1].write_text(
        verification_markdown(result, calibration=calibration, check_campaign=check_campaign, scope=scope),
        encoding="utf-8",
    )
    plot_verification(result, paths[2])
    return paths
