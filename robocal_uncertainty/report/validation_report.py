"""Report of a hold-out validation: JSON, Markdown, console table and the reliability plot."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.uncertainty.holdout import HoldoutValidation

__all__ = ["format_validation", "validation_to_dict", "write_validation_report"]

VALIDATION_FORMAT = "robocal_uncertainty/validation/1"


def validation_to_dict(validation: HoldoutValidation, *, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Strict-JSON view of a :class:`HoldoutValidation` (SI units, fractions in [0, 1])."""
    v = validation
    return {
        "format": VALIDATION_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "mode": v.mode,
        "frame_id": v.frame_id,
        "sources": list(v.sources),
        "seed": v.seed,
        "coverage_probability": v.coverage_probability,
        "n_held_out": v.n_held_out,
        "method": (
            "calibrate and evaluate on the training poses exactly as 'evaluate'; the predictive distribution of "
            "each held-out measurement is the Monte Carlo distribution of the prediction plus the measurement's "
            "own tracker noise; intervals are probabilistically symmetric, the 3-D region is JCGM 102's ellipsoid"
        ),
        "axes": [
            {
                "axis": a.axis,
                "rms_error_m": a.rms_error,
                "normalized_error_rms": a.normalized_rms,
                "inside_fraction": a.inside_fraction,
            }
            for a in v.axes
        ],
        "orientation_axes": [
            {
                "axis": a.axis,
                "rms_error_rad": a.rms_error,
                "normalized_error_rms": a.normalized_rms,
                "inside_fraction": a.inside_fraction,
            }
            for a in v.orientation_axes
        ],
        "region_inside_fraction": v.region_inside_fraction,
        "reliability": {
            "stated_coverage": v.levels.tolist(),
            "observed": {a.axis: a.reliability.tolist() for a in (*v.axes, *v.orientation_axes)},
            "observed_region": v.region_reliability.tolist(),
        },
        "folds": [
            {
                "n_train": f.n_train,
                "n_held_out": f.n_held_out,
                "residual_rms_after_m": f.rms_train_after,
                "lambda": f.lambda_,
                "model_adequate": f.model_adequate,
                "trustworthy": f.trustworthy,
                "model_error_standard_uncertainty_m": f.model_error_std.tolist(),
                "n_trials": f.n_trials,
                "model_error": f.model_error,
            }
            for f in v.folds
        ],
        "frame_comparison": None
        if v.frame_comparison is None
        else {
            "shift_m": v.frame_comparison.shift,
            "angle_rad": v.frame_comparison.angle,
            "displacement_rms_m": v.frame_comparison.displacement_rms,
            "limit_m": v.frame_comparison.limit,
            "moved": v.frame_comparison.moved,
            "method": "rigid fit of the calibration's predictions to the validation campaign's measured positions",
        },
        "extra_settings": dict(extra or {}),
    }


def _model_error(std: Any) -> str:
    """Model error u of a fold with the units of each component: (x, y, z) in um, then the
    rotation (rx, ry, rz) in mrad for a 6-DOF campaign."""
    values = [float(u) for u in std]
    text = "model error u = (" + ", ".join(f"{u * 1e6:.1f}" for u in values[:3]) + ") um"
    if len(values) > 3:
        text += ", (" + ", ".join(f"{u * 1e3:.3f}" for u in values[3:]) + ") mrad"
    return text


def format_validation(validation: HoldoutValidation) -> str:
    """Console table: per axis RMS error, normalised error RMS and coverage, then reliability."""
    v = validation
    p = 100 * v.coverage_probability
    lines = [
        f"Hold-out validation ({v.mode}, {len(v.folds)} fold(s), {v.n_held_out} held-out measurements, "
        f"frame {v.frame_id}, sources {', '.join(v.sources)})",
        f"{'axis':<6}{'RMS error / um':>16}{'normalised RMS':>16}{f'inside {p:g} % / %':>20}",
    ]
    for a in v.axes:
        lines.append(f"{a.axis:<6}{a.rms_error * 1e6:>16.1f}{a.normalized_rms:>16.3f}{100 * a.inside_fraction:>20.1f}")
    if v.orientation_axes:
        lines.append(f"{'axis':<6}{'RMS error / mrad':>16}{'normalised RMS':>16}{f'inside {p:g} % / %':>20}")
        for a in v.orientation_axes:
            lines.append(
                f"{a.axis:<6}{a.rms_error * 1e3:>16.4f}{a.normalized_rms:>16.3f}{100 * a.inside_fraction:>20.1f}"
            )
    lines.append(f"3-D region (JCGM 102) at {p:g} %: {100 * v.region_inside_fraction:.1f} % inside")
    kinds = [f.model_error for f in v.folds]
    if any(k != "none" for k in kinds):
        lines.append(
            f"model error: a field over the joint configurations in {kinds.count('field')} of {len(kinds)} fold(s), "
            f"independent from pose to pose in {kinds.count('independent')} (--independent-model-error, or the "
            "field not identified by the training poses)"
        )
    rot_names = "".join(f", {a.axis}" for a in v.orientation_axes)
    lines.append(f"reliability: stated p / observed % (x, y, z, 3-D{rot_names})")
    for i, level in enumerate(v.levels):
        obs = ", ".join(f"{100 * a.reliability[i]:.1f}" for a in v.axes)
        rot = "".join(f", {100 * a.reliability[i]:.1f}" for a in v.orientation_axes)
        lines.append(f"  {100 * level:5.1f} %: {obs}, {100 * v.region_reliability[i]:.1f}{rot}")
    if v.frame_comparison is not None:
        lines.append(f"validation campaign's frame: within the stated uncertainty; {v.frame_comparison.describe()}")
    lines.append("An honest statement has normalised RMS near 1 and observed near stated coverage.")
    lines.extend(trust_warnings(v))
    return "\n".join(lines)


def format_field_correction(check: Mapping[str, Any]) -> str:
    """The held-out accuracy with and without the model-error field's correction (``validate
    --field-correction``; `check` as ``FieldCorrectionCheck.to_dict`` writes it, m)."""
    before, after = check["uncorrected_rms_3d_m"], check["corrected_rms_3d_m"]
    per_axis = " / ".join(
        f"{b * 1e3:.3f} -> {a * 1e3:.3f}" for b, a in zip(check["uncorrected_rms_m"], check["corrected_rms_m"])
    )
    return (
        f"field correction (kriging, from each fold's training poses): held-out 3-D RMS {before * 1e3:.3f} mm "
        f"without, {after * 1e3:.3f} mm with it ({(after / before - 1) * 100:+.1f} %); per axis x / y / z {per_axis} "
        f"mm; corrected statement's u / uncorrected u: median {check['median_statement_ratio']:.2f} (the coverage "
        "above is the corrected statement's)"
    )


def trust_warnings(validation: HoldoutValidation) -> list[str]:
    """``warning: NOT TRUSTWORTHY`` lines when a fold's statement is flagged as ``evaluate`` flags it:
    the coverage measured here is then of a statement its own campaign cannot back."""
    flagged = [f for f in validation.folds if not f.trustworthy]
    if not flagged:
        return []
    note = flagged[0].trust_note or "NOT TRUSTWORTHY: too few residual degrees of freedom"
    which = (
        "the statement under test" if len(validation.folds) == 1 else f"{len(flagged)} of {len(validation.folds)} folds"
    )
    return [f"warning: {which} ({flagged[0].n_train} training poses): {note}"]


def _plot(validation: HoldoutValidation, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = validation
    fig, ax = plt.subplots(figsize=(5.0, 4.5))
    ax.plot([0.45, 1.0], [0.45, 1.0], color="0.6", lw=1.0, label="ideal")
    for a in v.axes:
        ax.plot(v.levels, a.reliability, marker="o", ms=3, label=a.axis)
    ax.plot(v.levels, v.region_reliability, marker="s", ms=3, color="k", label="3-D region")
    ax.set_xlabel("stated coverage probability p")
    ax.set_ylabel("observed fraction of held-out measurements inside")
    ax.set_title(f"Reliability ({v.n_held_out} held-out, {v.mode})")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_validation_report(
    directory: str | Path,
    validation: HoldoutValidation,
    *,
    extra: Mapping[str, Any] | None = None,
    overwrite: bool = True,
) -> Path:
    """Write ``validation.json``, ``validation.md`` and ``reliability.png`` into `directory`.

    Raises
    ------
    InputError
        `directory` exists as a file or cannot be created.
    """
    out = Path(directory)
    try:
        out.mkdir(parents=True, exist_ok=overwrite)
    except (FileExistsError, NotADirectoryError) as err:
        msg = f"cannot write the validation report to {out}: it exists and is not a directory"
        raise InputError(msg) from err
    except OSError as err:
        msg = f"cannot create {out}: {err.strerror}"
        raise InputError(msg) from err
    data = validation_to_dict(validation, extra=extra)
    (out / "validation.json").write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    _plot(validation, out / "reliability.png")
    table = format_validation(validation)
    md = [
        "# Hold-out validation of the uncertainty statement",
        "",
        data["method"] + ".",
        "",
        "```",
        table,
        "```",
        "",
        "![reliability](reliability.png)",
        "",
        "Folds: "
        + "; ".join(
            f"{f.n_train} training / {f.n_held_out} held out, residual RMS {f.rms_train_after * 1e6:.1f} um, "
            + ("model adequate" if f.model_adequate else _model_error(f.model_error_std))
            for f in validation.folds
        ),
        "",
    ]
    check = (extra or {}).get("field_correction")
    if isinstance(check, Mapping):
        md += [format_field_correction(check), ""]
    (out / "validation.md").write_text("\n".join(md), encoding="utf-8")
    return out
