"""Complete uncertainty report on disk: JSON, CSV, figures, Markdown and HTML.

The Markdown and HTML documents are rendered from the same list of blocks, so they
always say the same thing. Lengths are shown in mm (positions), µm (uncertainties) or
the unit named in the column header; every number is rounded to its uncertainty.

Reports scale with the number of test configurations. Up to
:data:`~robocal_uncertainty.report.configurations.DETAIL_LIMIT` (10) configurations,
each one is shown in full (Table 2, GUM comparison, budget, histograms). Beyond that the
documents give summary plots and a table of the worst configurations, show full detail
for a selection (by default the first
:data:`~robocal_uncertainty.report.configurations.DEFAULT_HISTOGRAMS` and the worst; see
the ``histograms`` argument of :func:`write_report`), and leave every configuration to
``configurations.csv`` and ``report.json``. With more than 10 configurations the documents
give a table of the 10 worst and statistics over all, with Table 2, the GUM comparison and the
budget in full only for the configurations with histograms and the worst one. A
150-configuration report takes a few seconds and a few MB (``benchmarks/bench_report.py``).

Files written by :func:`write_report`: ``report.json`` (see :mod:`.json_report`; every test
configuration), ``configurations.csv`` (one row per test configuration, see
:func:`~robocal_uncertainty.report.configurations.write_configurations_csv`), ``report.md``,
``report.html`` (self-contained: figures embedded as data URIs unless ``embed_images`` is
False), and the figures ``histograms_<i>.png`` and ``position_error_<i>.png`` per selected test
configuration (1-based, see ``histograms``; with orientation also
``rotation_histograms_<i>.png``), ``configurations.png`` and ``uncertainty_vs_reach.png`` when
there are two or more test configurations, ``lcurve.png``, ``parameters.png`` and
``sweep_<name>.png`` per sweep.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from robocal_uncertainty.core.identification import HELD_STD_RATIO, IdentificationResult
from robocal_uncertainty.core.observability import describe_dependency
from robocal_uncertainty.report.configurations import (
    DETAIL_LIMIT,
    ConfigurationSummary,
    HistogramSelection,
    select_configurations,
    summarize_configurations,
    write_configurations_csv,
)
from robocal_uncertainty.report.document_tree import (
    Block,
    BulletList,
    Figure,
    Heading,
    Paragraph,
    render_html,
    render_markdown,
    table,
)
from robocal_uncertainty.report.json_report import merge_warnings, software_version, write_report_json
from robocal_uncertainty.report.plots import (
    plot_axis_histograms,
    plot_configuration_summary,
    plot_lcurve,
    plot_parameter_distributions,
    plot_position_error,
    plot_rotation_histograms,
    plot_uncertainty_vs,
    plot_uncertainty_vs_reach,
)
from robocal_uncertainty.report.references import ROBOT_PAPER
from robocal_uncertainty.report.table2 import (
    RELATIVE_NOTE,
    budget_rows,
    format_significant,
    gum_verdict,
    round_to_uncertainty,
    table2_rows,
)
from robocal_uncertainty.uncertainty.calibration import CalibrationUncertainty, PoseUncertainty
from robocal_uncertainty.uncertainty.sources import SOURCE_DESCRIPTIONS
from robocal_uncertainty.uncertainty.sweeps import Sweep

__all__ = ["REPORT_FILES", "held_note", "write_report"]

REPORT_FILES = ("report.json", "report.md", "report.html", "configurations.csv")
"""Files every report directory holds, besides the PNG figures."""

_WORST_ROWS = 10
"""Rows of the worst-configurations table in the documents."""

_INTERVAL_NAMES = {
    "probabilistically_symmetric": "probabilistically symmetric",
    "shortest": "shortest",
}


def _mm(value: float, u: float) -> str:
    return round_to_uncertainty(value * 1e3, u * 1e3)


def _um(value: float) -> str:
    return format_significant(value * 1e6)


def _numbers(indices: Sequence[int]) -> str:
    """1-based configuration numbers, e.g. ``1, 2, 3 and 87``."""
    names = [str(i + 1) for i in indices]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _overview(result: CalibrationUncertainty, cs: ConfigurationSummary) -> str:
    """One summary line for many test configurations."""
    n = len(cs)
    w = cs.worst
    pos = ", ".join(f"{v * 1e3:.1f}" for v in cs.position[w])
    u_max = ", ".join(_um(v) for v in cs.standard_uncertainty.max(axis=0))
    big_max = ", ".join(_um(v) for v in cs.expanded_uncertainty.max(axis=0))
    gum = (
        f"GUM validated on all axes at {int(cs.gum_validated.sum())} of {n} configurations"
        if any(p.gum.applicable for p in result.poses)
        else "GUM comparison not applicable (non-smooth source enabled)"
    )
    return (
        f"{n} test configurations in frame `{result.frame_id}`: u_pos median "
        f"{_um(float(np.median(cs.position_uncertainty)))} µm, largest "
        f"{_um(float(cs.position_uncertainty[w]))} µm at test configuration {w + 1} "
        f"(position ({pos}) mm, reach {cs.reach[w] * 1e3:.0f} mm); largest u per axis ({u_max}) µm, "
        f"largest U ({big_max}) µm at p = {100 * result.coverage_probability:g} %; {gum}. "
        "Every configuration: `configurations.csv` and `report.json`."
    )


def _summary(result: CalibrationUncertainty, cs: ConfigurationSummary) -> list[Block]:
    items = []
    if len(result.poses) > DETAIL_LIMIT:
        items.append(_overview(result, cs))
    for i, pose in enumerate(result.poses if len(result.poses) <= DETAIL_LIMIT else ()):
        u = [a.standard_uncertainty for a in pose.axes]
        pos = ", ".join(_mm(a.estimate, a.standard_uncertainty) for a in pose.axes)
        us = ", ".join(_um(v) for v in u)
        big = ", ".join(_um(a.expanded_uncertainty) for a in pose.axes)
        u_pos = _um(float(np.linalg.norm(u)))
        items.append(
            f"Test configuration {i + 1}: position (x, y, z) in frame `{result.frame_id}` = ({pos}) mm; "
            f"u = ({us}) µm, U = ({big}) µm at p = {100 * result.coverage_probability:g} %; "
            f"u_pos = {u_pos} µm; GUM validated: {gum_verdict(pose)}."
        )
    if 1 < len(result.poses) <= DETAIL_LIMIT:
        items.append(
            f"Largest uncertainty: test configuration {cs.worst + 1} "
            f"(u_pos = {_um(float(cs.position_uncertainty[cs.worst]))} µm)."
        )
    ad = result.model_adequacy
    if ad.adequate:
        adequacy = (
            f"Model adequacy: the residuals are consistent with the stated tracker and encoder noise "
            f"(sum-of-squares test p = {ad.p_value:.3g} >= {ad.significance:g}); the residual source adds nothing."
        )
    else:
        std = [float(v) for v in ad.standard_uncertainty]
        u_m = f"({', '.join(_um(v) for v in std[:3])}) µm"
        if len(std) > 3:  # 6-DOF residuals: the rotation part is in rad
            u_m = f"{u_m} and rotation ({', '.join(f'{v * 1e3:.3f}' for v in std[3:])}) mrad"
        adequacy = (
            f"Model adequacy: the residuals exceed the stated noise (p = {ad.p_value:.3g} < {ad.significance:g}); "
            f"model error per axis of the measurement frame u = {u_m}, carried by the residual "
            "source when enabled."
        )
    items.append(adequacy)
    if not ad.trustworthy:
        items.append(f"**{ad.trust_note}.**")
    cal = result.calibration
    if not result.converged:
        conv = "NO"
    elif getattr(result, "convergence_tested", result.adaptive is not None):
        conv = "yes"
    else:
        # A fixed number of trials runs no convergence test: say so instead of "yes".
        conv = "not tested (fixed number of trials; --trials auto runs the JCGM 101 7.9 test)"
    items.append(
        f"Monte Carlo: {result.n_trials} trials"
        + (" (adaptive)" if result.adaptive is not None else "")
        + f", converged: {conv}, random seed {result.seed}, sources: {', '.join(result.settings.sources)}."
    )
    items.append(
        f"Calibration: residual RMS {_um(cal.rms_before)} µm before, "
        f"{_um(cal.rms_after)} µm after ({cal.n_poses} poses, λ = {cal.lambda_:.4g} by "
        f"{cal.lambda_method})."
    )
    return [Heading(2, "Summary"), BulletList(tuple(items))]


def _configurations(result: CalibrationUncertainty, cs: ConfigurationSummary) -> list[Block]:
    """Worst configurations first; with many, statistics over all of them."""
    n = len(cs)
    shown = cs.order[:_WORST_ROWS]
    which = f"the {len(shown)} worst of {n}" if len(shown) < n else f"all {n}"
    pct = f"{100 * result.coverage_probability:g}"
    blocks: list[Block] = [
        Heading(2, "Test configurations"),
        Paragraph(
            f"Sorted by u_pos = √(u_x² + u_y² + u_z²), worst first ({which}). Positions in frame "
            f"`{result.frame_id}`; reach = distance of the tool from the robot base; a₁ = largest "
            f"semi-axis of the JCGM 102 coverage ellipsoid at p = {pct} %. Every configuration, with "
            "joints, both coverage intervals and the GUM comparison, is in `configurations.csv`."
        ),
    ]
    rows = []
    for i in shown:
        u = cs.standard_uncertainty[i]
        rows.append(
            (
                str(i + 1),
                *(_mm(float(v), float(uu)) for v, uu in zip(cs.position[i], u)),
                f"{cs.reach[i] * 1e3:.0f}",
                *(_um(float(v)) for v in u),
                _um(float(cs.position_uncertainty[i])),
                _um(float(cs.region_semi_axes[i, 0])),
                gum_verdict(result.poses[i]),
            )
        )
    header: tuple[str, ...] = ("Config.", "x / mm", "y / mm", "z / mm", "reach / mm")
    header += ("u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm", "a₁ / µm", "GUM validated")
    blocks.append(table(header, rows))
    if n > DETAIL_LIMIT:
        columns = [*cs.standard_uncertainty.T, cs.position_uncertainty, cs.region_semi_axes[:, 0]]
        stats = []
        for label, fn in (("minimum", np.nanmin), ("median", np.nanmedian), ("maximum", np.nanmax)):
            stats.append((label, *(_um(float(fn(c))) if np.isfinite(c).any() else "n/a" for c in columns)))
        blocks.append(
            table(
                (f"Over {n} configurations", "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm", "a₁ / µm"),
                stats,
            )
        )
    return blocks


def _detail_note(result: CalibrationUncertainty, indices: Sequence[int], worst: int) -> list[Block]:
    """Which configurations a per-configuration section shows, when not all."""
    if len(indices) == len(result.poses):
        return []
    if not indices:
        return [Paragraph("No test configuration selected for detail; see `configurations.csv`.")]
    tail = f" ({worst + 1} is the worst)" if worst in indices else ""
    return [
        Paragraph(
            f"Shown for test configurations {_numbers(indices)}{tail} of {len(result.poses)}; "
            "every configuration is in `configurations.csv` and `report.json`."
        )
    ]


def _table2(result: CalibrationUncertainty, indices: Sequence[int], worst: int) -> list[Block]:
    blocks: list[Block] = [Heading(2, f"Uncertainty of the tool position (layout of {ROBOT_PAPER} Table 2)")]
    blocks += _detail_note(result, indices, worst)
    for i in indices:
        pose = result.poses[i]
        joints = ", ".join(f"{v:.4f}" for v in np.degrees(pose.joint_positions))
        kind = pose.axes[0].expanded_from
        blocks.append(Heading(3, f"Test configuration {i + 1}"))
        blocks.append(
            Paragraph(
                f"Positions in frame `{result.frame_id}` ({result.frame} frame). Joints / deg: ({joints}). "
                f"{result.n_trials} trials, coverage probability "
                f"{100 * result.coverage_probability:g} %, {_INTERVAL_NAMES.get(kind, kind)} "
                f"interval, random seed {result.seed}, sources: {', '.join(result.settings.sources)}. "
                f"GUM validated: {gum_verdict(pose)}."
            )
        )
        rows = [(label, *cells) for label, cells in table2_rows(pose, "mm")]
        blocks.append(table(("Quantity", "x", "y", "z"), rows))
        blocks.append(Paragraph(RELATIVE_NOTE))
        if pose.region is not None:
            r = pose.region
            blocks.append(
                Paragraph(
                    f"JCGM 102 coverage region (ellipsoid, p = {100 * r.coverage_probability:g} %): "
                    f"k_p = {r.coverage_factor:.3f} from the Monte Carlo values "
                    f"(a trivariate normal would give {r.normal_coverage_factor:.3f})."
                )
            )
        blocks += _orientation(pose)
    return blocks


def _mrad(value: float) -> str:
    return format_significant(value * 1e3)


def _orientation(pose: PoseUncertainty) -> list[Block]:
    """Orientation of one test configuration: mean quaternion, per-axis statement in mrad."""
    o = pose.orientation
    if o is None:
        return []
    quat = ", ".join(f"{v:.6f}" for v in o.mean_quaternion)
    text = (
        f"Tool orientation: mean (chordal L2) quaternion (x, y, z, w) = ({quat}). Deviations are "
        "rotations about the fixed x, y, z axes of the output frame (ROS PoseWithCovariance), in mrad."
    )
    if not o.fully_determined:
        dirs = "; ".join("(" + ", ".join(f"{c:+.3f}" for c in d) + ")" for d in o.undetermined_directions)
        text += (
            f" The campaign cannot determine the rotation about {dirs} (output frame): no parameter the "
            "measurements see moves it, so the axes that overlap it are reported as undetermined."
        )
    rows: list[tuple[str, ...]] = []
    labels: tuple[tuple[str, Callable[[int], str]], ...] = (
        ("u / mrad", lambda j: _mrad(o.axes[j].standard_uncertainty)),
        ("U / mrad", lambda j: _mrad(o.axes[j].expanded_uncertainty)),
        ("interval / mrad", lambda j: f"[{_mrad(o.axes[j].interval.low)}, {_mrad(o.axes[j].interval.high)}]"),
        ("GUM u / mrad", lambda j: _mrad(float(o.gum.standard_uncertainty[j]))),
    )
    for label, cell in labels:
        rows.append((label, *(cell(j) if o.determined[j] else "undetermined" for j in range(3))))
    return [Paragraph(text), table(("Quantity", "rx", "ry", "rz"), rows)]


def _budget(budget: Mapping[str, CalibrationUncertainty], indices: Sequence[int]) -> list[Block]:
    blocks: list[Block] = [
        Heading(2, "Uncertainty budget"),
        Paragraph("Each row is a Monte Carlo run with that source alone; u in µm."),
    ]
    n_test = min(len(r.poses) for r in budget.values())
    if n_test > DETAIL_LIMIT:
        rows = []
        for name, res in budget.items():
            u_pos = np.array([np.linalg.norm([a.standard_uncertainty for a in p.axes]) for p in res.poses[:n_test]])
            rows.append((name, _um(float(np.median(u_pos))), _um(float(u_pos.max())), str(int(np.argmax(u_pos)) + 1)))
        blocks.append(
            table((f"Source (over {n_test} configurations)", "median u_pos / µm", "max u_pos / µm", "at config."), rows)
        )
    indices = [i for i in indices if i < n_test] if n_test > DETAIL_LIMIT else list(range(n_test))
    for i in indices:
        if n_test > 1:
            blocks.append(Heading(3, f"Test configuration {i + 1}"))
        blocks.append(
            table(
                ("Source", "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm"),
                budget_rows(budget, i),
            )
        )
    return blocks


def _gum(result: CalibrationUncertainty, indices: Sequence[int], cs: ConfigurationSummary) -> list[Block]:
    blocks: list[Block] = [
        Heading(2, "Comparison with the GUM (JCGM 101 §8)"),
        Paragraph(
            "First-order propagation (law of propagation of uncertainty) against the Monte "
            "Carlo probabilistically symmetric interval; validated when both endpoint "
            "differences d_low, d_high are within the numerical tolerance δ."
        ),
    ]
    n = len(result.poses)
    if n > DETAIL_LIMIT and any(p.gum.applicable for p in result.poses):
        failed = [i for i in range(n) if not cs.gum_validated[i]]
        listed = _numbers(failed[:30]) + (f" and {len(failed) - 30} more" if len(failed) > 30 else "")
        blocks.append(
            Paragraph(
                f"Validated on all three axes at {n - len(failed)} of {n} test configurations"
                + (f"; not at {listed}." if failed else ".")
            )
        )
    blocks += _detail_note(result, indices, cs.worst)
    for i in indices:
        pose = result.poses[i]
        g = pose.gum
        if len(result.poses) > 1:
            blocks.append(Heading(3, f"Test configuration {i + 1}"))
        if not g.applicable:
            blocks.append(Paragraph("Not applicable: a non-smooth source (lambda, n_poses, pose_choice) is enabled."))
        rows = []
        for j, name in enumerate("xyz"):
            a = pose.axes[j]
            rows.append(
                (
                    name,
                    _mm(a.estimate, a.standard_uncertainty),
                    _mm(float(g.estimate[j]), a.standard_uncertainty),
                    _um(a.standard_uncertainty),
                    _um(float(g.standard_uncertainty[j])),
                    f"{g.coverage_factor:.3f}",
                    format_significant(a.coverage_factor, 3),
                    _um(float(g.d_low[j])),
                    _um(float(g.d_high[j])),
                    _um(float(g.delta[j])),
                    "yes" if g.validated[j] else "no",
                )
            )
        blocks.append(
            table(
                (
                    "Axis",
                    "y MC / mm",
                    "y GUM / mm",
                    "u MC / µm",
                    "u GUM / µm",
                    "k GUM",
                    "k MC",
                    "d_low / µm",
                    "d_high / µm",
                    "δ / µm",
                    "validated",
                ),
                rows,
            )
        )
    return blocks


def _param_display(kind: str) -> tuple[float, str, float, str]:
    if kind == "angle":
        return 180.0 / math.pi, "deg", 1e3 * 180.0 / math.pi, "mdeg"
    return 1e3, "mm", 1e6, "µm"


def _weighting_lines(cal: IdentificationResult) -> tuple[str, ...]:
    """How the residual components were weighted (measurements mixing m and rad only)."""
    m = cal.measurement
    if m.weights is None:
        return ()

    def shown(values: Sequence[float]) -> str:
        return ", ".join(
            f"{name} {v * (1e6 if unit == 'm' else 1e3):.3g} {'µm' if unit == 'm' else 'mrad'}"
            for name, unit, v in zip(m.component_names, m.component_units, values)
        )

    used = (1.0 / m.weights).tolist()
    how = {
        "stated": "the instrument's stated standard uncertainties",
        "variance_components": (
            f"standard deviations estimated from the residual scatter (variance components, "
            f"{cal.weighting_iterations} fits; never below the stated values)"
        ),
    }.get(cal.weighting, cal.weighting)
    return (
        f"residuals weighted by {how}: {shown(used)}",
        f"stated instrument uncertainties: {shown(np.asarray(cast(Any, m).std, dtype=np.float64).tolist())}",
    )


def _parameter_rows(cal: IdentificationResult, result: CalibrationUncertainty) -> list[tuple[str, ...]]:
    """One row per estimated parameter: nominal, estimate and error rounded to u, u (MC, linearised)."""
    kinds = dict(zip(cal.model.layout.names, cal.model.layout.kinds))
    mc = dict(zip(result.parameter_names, result.parameters))
    rows: list[tuple[str, ...]] = []
    held = cal.held_by_regularisation
    for i, name in enumerate(cal.parameter_names):
        if not cal.estimated[i]:
            continue
        scale, unit, uscale, uunit = _param_display(kinds.get(name, "length"))
        summary = mc.get(name)
        u = summary.standard_uncertainty if summary is not None else float(cal.linearized_std[i])
        if held[i]:
            # The Tikhonov term, not the data, fixes it: no u of a measurement to state.
            data_u = float(cal.data_only_std[i]) if cal.data_only_std is not None else math.inf
            u = data_u if math.isfinite(data_u) else u
            mc_cell = lin_cell = held_note(data_u, kinds.get(name, "length"))
        else:
            mc_cell = f"{format_significant(u * uscale)} {uunit}" if summary is not None else "n/a"
            lin_cell = f"{format_significant(float(cal.linearized_std[i]) * uscale)} {uunit}"
        rows.append(
            (
                name,
                f"{cal.nominal[i] * scale:.6g} {unit}",
                f"{round_to_uncertainty(cal.estimate[i] * scale, u * scale)} {unit}",
                f"{round_to_uncertainty((cal.estimate[i] - cal.nominal[i]) * uscale, u * uscale)} {uunit}",
                mc_cell,
                lin_cell,
            )
        )
    return rows


def _dependency_blocks(cal: IdentificationResult) -> list[Block]:
    """Why the candidates left at nominal are not identifiable, and the other dependencies."""
    blocks: list[Block] = []
    missing = [n for i, n in enumerate(cal.parameter_names) if cal.candidates[i] and not cal.estimated[i]]
    if missing:
        reasons = []
        for name in missing:
            why = [d for d in cal.dependencies if d.split(" ", 1)[0] == name]
            text = "; ".join(describe_dependency(d) for d in why)
            reasons.append(f"{name}: {text or 'not identifiable from position data'}")
        blocks.append(Heading(3, "Not identifiable (kept at nominal)"))
        blocks.append(BulletList(tuple(reasons)))
    others = [d for d in cal.dependencies if d.split(" ", 1)[0] not in missing]
    if others:
        blocks.append(Paragraph("Other dependencies: " + "; ".join(describe_dependency(d) for d in others)))
    return blocks


def _calibration(cal: IdentificationResult, result: CalibrationUncertainty) -> list[Block]:
    blocks: list[Block] = [
        Heading(2, "Calibration"),
        BulletList(
            (
                (
                    f"λ = {cal.lambda_:.4g} (scaled units), method {cal.lambda_method}; L-curve corner "
                    f"{cal.lcurve.corner_lambda:.4g}, GCV minimum {cal.lcurve.gcv_lambda:.4g}"
                ),
                (
                    f"residual RMS / max before: {_um(cal.rms_before)} / {_um(cal.max_before)} µm; "
                    f"after: {_um(cal.rms_after)} / {_um(cal.max_after)} µm"
                ),
                f"condition number of the scaled Jacobian: {cal.condition_number:.3g}",
                f"iterations: {cal.iterations}, converged: {'yes' if cal.converged else 'NO'} ({cal.message})",
                f"poses: {cal.n_poses}; base initialised: {cal.base_initialised}; tool point initialised: "
                f"{cal.tool_initialised}",
                f"estimated parameters: {int(cal.estimated.sum())} of {int(cal.candidates.sum())} candidates",
                *_weighting_lines(cal),
            )
        ),
        Paragraph(
            "Estimate rounded to its Monte Carlo standard uncertainty; lengths in mm with u in µm, "
            "angles in deg with u in mdeg. A parameter *held by regularisation* is one the data "
            f"alone determine more than {HELD_STD_RATIO:g} times less well than the regularised fit "
            "states: the Tikhonov term fixes it, its regularised u is no measurement's, and the "
            "data-only u (lambda = 0) is given instead."
        ),
    ]
    rows = _parameter_rows(cal, result)
    blocks.append(
        table(
            (
                "Parameter",
                "Nominal",
                "Estimate",
                "Error",
                "u (Monte Carlo)",
                "u (linearised)",
            ),
            rows,
        )
    )
    blocks += _dependency_blocks(cal)
    return blocks


def held_note(data_only_std: float, kind: str, *, micro: str = "µ") -> str:
    """How a parameter held by regularisation is shown instead of its u: its data-only u.

    ``data_only_std`` in m or rad (``inf``: the data carry no information); ``kind`` is
    ``"length"`` or ``"angle"``. Lengths above 1 mm in mm, else µm (``micro`` + m: ``"u"``
    for the console); angles in deg or mdeg.
    """
    if not math.isfinite(data_only_std):
        return "held by regularisation; not identifiable from the data alone"
    scale, unit, uscale, uunit = _param_display(kind)
    value, shown = (data_only_std * scale, unit) if data_only_std * uscale >= 1000 else (data_only_std * uscale, uunit)
    return f"held by regularisation; data-only u = {format_significant(value)} {shown.replace('µ', micro)}"


def _settings(
    result: CalibrationUncertainty,
    campaign_source: str | None,
    extra_settings: Mapping[str, object] | None,
    robot_name: str,
) -> list[Block]:
    s = result.settings
    lam_range = (
        "n/a" if result.lambda_range is None else f"[{result.lambda_range[0]:.4g}, {result.lambda_range[1]:.4g}]"
    )
    items = [
        f"software: robocal_uncertainty {software_version()}",
        f"robot: {robot_name}; campaign: {campaign_source or 'not stated'}",
        (
            f"random seed: {result.seed}; block size: {result.block_size}; trials: {result.n_trials}; "
            f"coverage probability: {result.coverage_probability:g}"
        ),
        f"Monte Carlo backend: {'not recorded' if result.backend is None else result.backend.describe()}",
        f"tracker noise: uniform ±(a + b·L), a = {s.tracker_noise.a * 1e6:g} µm, b = {s.tracker_noise.b * 1e6:g} µm/m",
        f"encoder noise: uniform ±{math.degrees(s.encoder_noise.half_width):g} deg"
        + (
            f", prismatic joints ±{s.encoder_noise.linear_half_width * 1e6:g} µm"
            if any(result.calibration.model.prismatic)
            else ""
        ),
        f"lambda range (lambda source): {lam_range}; λ* = {result.lambda_star:.4g}",
        (
            f"min_poses: {s.min_poses if s.min_poses is not None else 'default'}; "
            f"subset size: {s.subset_size if s.subset_size is not None else 'default'}"
        ),
        f"re-identification: {s.jacobian} Jacobian, {s.gauss_newton_iterations} iterations",
    ]
    if result.adaptive is not None:
        a = result.adaptive
        items.append(
            f"adaptive (JCGM 101 §7.9): n_dig = {a.n_dig}, {a.n_sequences} sequences of "
            f"{a.sequence_trials} trials, converged: {'yes' if a.converged else 'NO'}"
        )
    for key, value in (extra_settings or {}).items():
        items.append(f"{key}: {value}")
    blocks: list[Block] = [
        Heading(2, "Settings and reproducibility"),
        BulletList(tuple(items)),
        Heading(3, "Uncertainty sources"),
        table(
            ("Source", "Description"),
            [(name, SOURCE_DESCRIPTIONS.get(name, "")) for name in s.sources],
        ),
    ]
    return blocks


def _configuration_figures(result: CalibrationUncertainty, out: Path, cs: ConfigurationSummary) -> list[Figure]:
    """The figures over all test configurations (two or more)."""
    figures: list[Figure] = []
    plot_configuration_summary(result, out / "configurations.png", summary=cs)
    figures.append(
        Figure(
            "configurations.png",
            "Standard uncertainty per axis and u_pos per test configuration, worst ringed; "
            "semi-axes of the JCGM 102 coverage ellipsoid",
        )
    )
    plot_uncertainty_vs_reach(result, out / "uncertainty_vs_reach.png", summary=cs)
    figures.append(
        Figure(
            "uncertainty_vs_reach.png",
            "Standard uncertainty against the distance of the tool from the robot base",
        )
    )
    return figures


def _pose_figures(result: CalibrationUncertainty, out: Path, selected: Sequence[int]) -> list[Figure]:
    """Histograms and position error (and rotation histograms) of each selected test configuration."""
    figures: list[Figure] = []
    for i in selected:
        name = f"histograms_{i + 1}.png"
        plot_axis_histograms(result, out / name, pose=i)
        figures.append(
            Figure(
                name,
                f"Tool position per axis, test configuration {i + 1}, with mean, "
                f"coverage intervals and the GUM normal pdf (cf. {ROBOT_PAPER} Fig. 10)",
            )
        )
        name = f"position_error_{i + 1}.png"
        plot_position_error(result, out / name, pose=i)
        figures.append(
            Figure(
                name,
                f"Position error |p − p̄|, test configuration {i + 1} (cf. {ROBOT_PAPER} Fig. 11)",
            )
        )
        orientation = result.poses[i].orientation
        # No figure of three empty panels: with no rotation determined there is nothing to draw
        # (the orientation section says which rotations are undetermined and why).
        if orientation is not None and any(orientation.determined):
            name = f"rotation_histograms_{i + 1}.png"
            plot_rotation_histograms(result, out / name, pose=i)
            figures.append(
                Figure(
                    name,
                    f"Tool orientation per axis (rx, ry, rz about the fixed axes of {result.frame_id}, deviation "
                    f"from the mean, mrad), test configuration {i + 1}, with coverage intervals and the GUM normal pdf",
                )
            )
    return figures


def _fit_figures(result: CalibrationUncertainty, out: Path, sweeps: Sequence[Sweep]) -> list[Figure]:
    """The L-curve, the parameter distributions and one figure per sweep."""
    figures: list[Figure] = []
    plot_lcurve(result.calibration, out / "lcurve.png")
    figures.append(Figure("lcurve.png", "L-curve and GCV with the chosen λ"))
    if result.parameter_names:
        plot_parameter_distributions(result, out / "parameters.png")
        figures.append(
            Figure(
                "parameters.png",
                f"Monte Carlo distributions of the identified parameter errors (cf. {ROBOT_PAPER} Fig. 5); "
                "hatched panels marked 'held by regularisation': the Tikhonov term, not the data, fixes them",
            )
        )
    for sw in sweeps:
        name = f"sweep_{''.join(c if c.isalnum() else '_' for c in sw.name)}.png"
        plot_uncertainty_vs(
            sw.values,
            sw.standard_uncertainty,
            sw.xlabel,
            out / name,
            reference=sw.reference,
            log_x=sw.log_x,
        )
        figures.append(Figure(name, f"Standard uncertainty vs {sw.xlabel} (cf. {ROBOT_PAPER} Figs. 7-9)"))
    return figures


def _sweep_blocks(sweeps: Sequence[Sweep]) -> list[Block]:
    """The Sweeps section: one table of standard uncertainties per sweep."""
    blocks: list[Block] = [Heading(2, "Sweeps")]
    for sw in sweeps:
        rows = [
            (f"{v:.4g}", *(_um(float(x)) for x in u), _um(float(np.linalg.norm(u))))
            for v, u in zip(sw.values, sw.standard_uncertainty)
        ]
        blocks.append(Heading(3, f"{sw.name} ({sw.n_trials or '?'} trials per point)"))
        blocks.append(table((sw.xlabel, "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm"), rows))
    return blocks


def _result_sections(
    result: CalibrationUncertainty,
    cs: ConfigurationSummary,
    detail: Sequence[int],
    budget: Mapping[str, CalibrationUncertainty] | None,
    sweeps: Sequence[Sweep] | None,
) -> list[Block]:
    """The report's sections from the summary to the sweeps (the same for Markdown and HTML)."""
    blocks = _summary(result, cs)
    if len(result.poses) > 1:
        blocks += _configurations(result, cs)
    blocks += _table2(result, detail, cs.worst)
    if budget:
        blocks += _budget(budget, detail)
    blocks += _gum(result, detail, cs)
    blocks += _calibration(result.calibration, result)
    if sweeps:
        blocks += _sweep_blocks(sweeps)
    return blocks


def _detail_selection(histograms: HistogramSelection, n_test: int, worst: int) -> tuple[tuple[int, ...], list[int]]:
    """Configurations with histograms, and those shown in full (every one up to DETAIL_LIMIT)."""
    selected = select_configurations(histograms, n_test, worst)
    detail = list(range(n_test)) if n_test <= DETAIL_LIMIT else sorted({*selected, worst})
    return selected, detail


def _warning_list(warnings: Sequence[str]) -> Block:
    """The Warnings section's body: the list, or "None."."""
    return BulletList(tuple(warnings)) if warnings else Paragraph("None.")


def write_report(
    directory: str | Path,
    result: CalibrationUncertainty,
    *,
    robot_name: str,
    budget: Mapping[str, CalibrationUncertainty] | None = None,
    sweeps: Sequence[Sweep] | None = None,
    campaign_source: str | None = None,
    extra_settings: Mapping[str, object] | None = None,
    title: str | None = None,
    embed_images: bool = True,
    input_warnings: Sequence[str] = (),
    histograms: HistogramSelection = None,
) -> Path:
    """Write the full uncertainty report into `directory` (created if needed).

    The files written, and how large reports are summarised: see the module documentation.

    Parameters
    ----------
    directory : str or Path
    result : CalibrationUncertainty
    robot_name : str
    budget : mapping of str to CalibrationUncertainty, optional
        Single-source runs for the uncertainty budget.
    sweeps : sequence of Sweep, optional
        Uncertainty vs lambda / number of equations (see :mod:`.sweeps`).
    campaign_source : str, optional
        Where the campaign came from.
    extra_settings : mapping, optional
        Further settings to record (JSON-serialisable).
    title : str, optional
        Document title; default names the robot.
    embed_images : bool
        Embed the PNGs in the HTML (True) or link them by file name.
    input_warnings : sequence of str
        Warnings about the input data, e.g. ``campaign.metadata.get("warnings", [])`` of a
        campaign recovered from a truncated file; listed first in ``report.json``'s
        ``warnings`` and in the Warnings section of ``report.md``/``report.html``.
    histograms : None, int, "all" or sequence of int
        Test configurations that get per-configuration histogram figures, as
        :func:`~robocal_uncertainty.report.configurations.select_configurations` reads it (two
        figures each, three with orientation: about 0.25-0.4 MB and 0.3-0.5 s per configuration).

    Returns
    -------
    Path
        The report directory.

    Raises
    ------
    ConfigError
        `histograms` is not one of those forms or names a configuration that does not exist.
    """
    warnings = merge_warnings(input_warnings, result.warnings)
    cs = summarize_configurations(result)
    selected, detail = _detail_selection(histograms, len(result.poses), cs.worst)
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    title = title or f"Calibration uncertainty report: {robot_name}"
    write_report_json(
        out / "report.json",
        result,
        robot_name=robot_name,
        campaign_source=campaign_source,
        extra_settings=extra_settings,
        budget=budget,
        sweeps=sweeps,
        input_warnings=input_warnings,
    )
    write_configurations_csv(out / "configurations.csv", result, cs)
    figures = _configuration_figures(result, out, cs) if len(result.poses) > 1 else []
    figures += _pose_figures(result, out, selected)
    figures += _fit_figures(result, out, sweeps or ())
    blocks: list[Block] = [Heading(1, title), *_result_sections(result, cs, detail, budget, sweeps)]
    blocks += [Heading(2, "Figures"), *figures, *_settings(result, campaign_source, extra_settings, robot_name)]
    blocks += [Heading(2, "Warnings"), _warning_list(warnings)]
    (out / "report.md").write_text(render_markdown(blocks), encoding="utf-8")
    (out / "report.html").write_text(render_html(blocks, title, out, embed=embed_images), encoding="utf-8")
    return out
