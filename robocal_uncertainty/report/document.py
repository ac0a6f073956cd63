"""Complete uncertainty report on disk: JSON, figures, Markdown and HTML.

The Markdown and HTML documents are rendered from the same list of blocks, so they
always say the same thing. Lengths are shown in mm (positions), µm (uncertainties) or
the unit named in the column header; every number is rounded to its uncertainty.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.report.json_report import merge_warnings, software_version, write_report_json
from robocal_uncertainty.report.plots import (
    plot_axis_histograms,
    plot_lcurve,
    plot_parameter_distributions,
    plot_position_error,
    plot_uncertainty_vs,
)
from robocal_uncertainty.report.sweeps import Sweep
from robocal_uncertainty.report.table2 import (
    budget_rows,
    format_significant,
    gum_verdict,
    round_to_uncertainty,
    table2_rows,
)
from robocal_uncertainty.uncertainty.calibration_mc import CalibrationUncertainty
from robocal_uncertainty.uncertainty.sources import SOURCE_DESCRIPTIONS

__all__ = ["REPORT_FILES", "write_report"]

REPORT_FILES = ("report.json", "report.md", "report.html")
"""Files every report directory holds, besides the PNG figures."""

_INTERVAL_NAMES = {
    "probabilistically_symmetric": "probabilistically symmetric",
    "shortest": "shortest",
}


@dataclass(frozen=True)
class _Heading:
    level: int
    text: str


@dataclass(frozen=True)
class _Para:
    text: str


@dataclass(frozen=True)
class _List:
    items: tuple[str, ...]


@dataclass(frozen=True)
class _Table:
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class _Image:
    file: str
    caption: str


_Block = _Heading | _Para | _List | _Table | _Image


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> _Table:
    return _Table(tuple(header), tuple(tuple(r) for r in rows))


def _mm(value: float, u: float) -> str:
    return round_to_uncertainty(value * 1e3, u * 1e3)


def _um(value: float) -> str:
    return format_significant(value * 1e6)


def _summary(result: CalibrationUncertainty) -> list[_Block]:
    items = []
    for i, pose in enumerate(result.poses):
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
    ad = result.model_adequacy
    if ad.adequate:
        adequacy = (
            f"Model adequacy: the residuals are consistent with the stated tracker and encoder noise "
            f"(sum-of-squares test p = {ad.p_value:.3g} >= {ad.significance:g}); the residual source adds nothing."
        )
    else:
        u_m = ", ".join(_um(v) for v in ad.standard_uncertainty)
        adequacy = (
            f"Model adequacy: the residuals exceed the stated noise (p = {ad.p_value:.3g} < {ad.significance:g}); "
            f"model error per axis of the measurement frame u = ({u_m}) µm, carried by the residual "
            "source when enabled."
        )
    items.append(adequacy)
    cal = result.calibration
    conv = "yes" if result.converged else "NO"
    items.append(
        f"Monte Carlo: {result.n_trials} trials"
        + (" (adaptive)" if result.adaptive is not None else "")
        + f", converged: {conv}, seed {result.seed}, sources: {', '.join(result.settings.sources)}."
    )
    items.append(
        f"Calibration: residual RMS {_um(cal.rms_before)} µm before, "
        f"{_um(cal.rms_after)} µm after ({cal.n_poses} poses, λ = {cal.lambda_:.4g} by "
        f"{cal.lambda_method})."
    )
    return [_Heading(2, "Summary"), _List(tuple(items))]


def _table2(result: CalibrationUncertainty) -> list[_Block]:
    blocks: list[_Block] = [_Heading(2, "Uncertainty of the tool position (seed Table 2)")]
    for i, pose in enumerate(result.poses):
        joints = ", ".join(f"{v:.4f}" for v in np.degrees(pose.joint_positions))
        kind = pose.axes[0].expanded_from
        blocks.append(_Heading(3, f"Test configuration {i + 1}"))
        blocks.append(
            _Para(
                f"Positions in frame `{result.frame_id}` ({result.frame} frame). Joints / deg: ({joints}). "
                f"{result.n_trials} trials, coverage probability "
                f"{100 * result.coverage_probability:g} %, {_INTERVAL_NAMES.get(kind, kind)} "
                f"interval, seed {result.seed}, sources: {', '.join(result.settings.sources)}. "
                f"GUM validated: {gum_verdict(pose)}."
            )
        )
        rows = [(label, *cells) for label, cells in table2_rows(pose, "mm")]
        blocks.append(_table(("Quantity", "x", "y", "z"), rows))
        if pose.region is not None:
            r = pose.region
            blocks.append(
                _Para(
                    f"JCGM 102 coverage region (ellipsoid, p = {100 * r.coverage_probability:g} %): "
                    f"k_p = {r.coverage_factor:.3f} from the Monte Carlo values "
                    f"(a trivariate normal would give {r.normal_coverage_factor:.3f})."
                )
            )
    return blocks


def _budget(budget: Mapping[str, CalibrationUncertainty]) -> list[_Block]:
    blocks: list[_Block] = [
        _Heading(2, "Uncertainty budget"),
        _Para("Each row is a Monte Carlo run with that source alone; u in µm."),
    ]
    n_test = min(len(r.poses) for r in budget.values())
    for i in range(n_test):
        if n_test > 1:
            blocks.append(_Heading(3, f"Test configuration {i + 1}"))
        blocks.append(
            _table(
                ("Source", "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm"),
                budget_rows(budget, i),
            )
        )
    return blocks


def _gum(result: CalibrationUncertainty) -> list[_Block]:
    blocks: list[_Block] = [
        _Heading(2, "Comparison with the GUM (JCGM 101 §8)"),
        _Para(
            "First-order propagation (law of propagation of uncertainty) against the Monte "
            "Carlo probabilistically symmetric interval; validated when both endpoint "
            "differences d_low, d_high are within the numerical tolerance δ."
        ),
    ]
    for i, pose in enumerate(result.poses):
        g = pose.gum
        if len(result.poses) > 1:
            blocks.append(_Heading(3, f"Test configuration {i + 1}"))
        if not g.applicable:
            blocks.append(_Para("Not applicable: a non-smooth source (lambda, n_poses, pose_choice) is enabled."))
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
            _table(
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


def _calibration(cal: IdentificationResult, result: CalibrationUncertainty) -> list[_Block]:
    kinds = dict(zip(cal.model.layout.names, cal.model.layout.kinds))
    mc = dict(zip(result.parameter_names, result.parameters))
    blocks: list[_Block] = [
        _Heading(2, "Calibration"),
        _List(
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
                f"poses: {cal.n_poses}; base initialised: {cal.base_initialised}",
                f"estimated parameters: {int(cal.estimated.sum())} of {int(cal.candidates.sum())} candidates",
            )
        ),
        _Para(
            "Estimate rounded to its Monte Carlo standard uncertainty; lengths in mm with u in µm, "
            "angles in deg with u in mdeg."
        ),
    ]
    rows = []
    for i, name in enumerate(cal.parameter_names):
        if not cal.estimated[i]:
            continue
        scale, unit, uscale, uunit = _param_display(kinds.get(name, "length"))
        summary = mc.get(name)
        u = summary.standard_uncertainty if summary is not None else float(cal.linearized_std[i])
        rows.append(
            (
                name,
                f"{cal.nominal[i] * scale:.6g} {unit}",
                f"{round_to_uncertainty(cal.estimate[i] * scale, u * scale)} {unit}",
                f"{round_to_uncertainty((cal.estimate[i] - cal.nominal[i]) * uscale, u * uscale)} {uunit}",
                f"{format_significant(u * uscale)} {uunit}" if summary is not None else "n/a",
                f"{format_significant(float(cal.linearized_std[i]) * uscale)} {uunit}",
            )
        )
    blocks.append(
        _table(
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
    missing = [n for i, n in enumerate(cal.parameter_names) if cal.candidates[i] and not cal.estimated[i]]
    if missing:
        reasons = []
        for name in missing:
            why = [d for d in cal.dependencies if d.split(" ", 1)[0] == name]
            reasons.append(f"{name}: {'; '.join(why) if why else 'not identifiable from position data'}")
        blocks.append(_Heading(3, "Not identifiable (kept at nominal)"))
        blocks.append(_List(tuple(reasons)))
    others = [d for d in cal.dependencies if d.split(" ", 1)[0] not in missing]
    if others:
        blocks.append(_Para("Other dependencies: " + "; ".join(others)))
    return blocks


def _settings(
    result: CalibrationUncertainty,
    campaign_source: str | None,
    extra_settings: Mapping[str, object] | None,
    robot_name: str,
) -> list[_Block]:
    s = result.settings
    lam_range = (
        "n/a" if result.lambda_range is None else f"[{result.lambda_range[0]:.4g}, {result.lambda_range[1]:.4g}]"
    )
    items = [
        f"software: robocal_uncertainty {software_version()}",
        f"robot: {robot_name}; campaign: {campaign_source or 'not stated'}",
        (
            f"seed: {result.seed}; block size: {result.block_size}; trials: {result.n_trials}; "
            f"coverage probability: {result.coverage_probability:g}"
        ),
        f"tracker noise: uniform ±(a + b·L), a = {s.tracker_noise.a * 1e6:g} µm, b = {s.tracker_noise.b * 1e6:g} µm/m",
        f"encoder noise: uniform ±{math.degrees(s.encoder_noise.half_width):g} deg",
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
    blocks: list[_Block] = [
        _Heading(2, "Settings and reproducibility"),
        _List(tuple(items)),
        _Heading(3, "Uncertainty sources"),
        _table(
            ("Source", "Description"),
            [(name, SOURCE_DESCRIPTIONS.get(name, "")) for name in s.sources],
        ),
    ]
    return blocks


def _render_md(blocks: Sequence[_Block]) -> str:
    out: list[str] = []
    for b in blocks:
        if isinstance(b, _Heading):
            out.append("#" * b.level + " " + b.text)
        elif isinstance(b, _Para):
            out.append(b.text)
        elif isinstance(b, _List):
            out.append("\n".join(f"- {item}" for item in b.items))
        elif isinstance(b, _Table):
            lines = [
                "| " + " | ".join(b.header) + " |",
                "|" + "|".join("---" for _ in b.header) + "|",
            ]
            lines.extend("| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in b.rows)
            out.append("\n".join(lines))
        else:
            out.append(f"![{b.caption}]({b.file})\n\n*{b.caption}*")
    return "\n\n".join(out) + "\n"


_CSS = (
    "body{font-family:sans-serif;max-width:70em;margin:2em auto;padding:0 1em;color:#222}"
    "table{border-collapse:collapse;margin:1em 0}"
    "th,td{border:1px solid #aaa;padding:.25em .6em;text-align:right}"
    "th:first-child,td:first-child{text-align:left}th{background:#eee}"
    "img{max-width:100%}figure{margin:1em 0}figcaption{font-style:italic}"
)


def _render_html(blocks: Sequence[_Block], title: str, directory: Path, embed: bool) -> str:
    e = html.escape
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{e(title)}</title><style>{_CSS}</style></head><body>",
    ]
    for b in blocks:
        if isinstance(b, _Heading):
            out.append(f"<h{b.level}>{e(b.text)}</h{b.level}>")
        elif isinstance(b, _Para):
            out.append(f"<p>{e(b.text)}</p>")
        elif isinstance(b, _List):
            out.append("<ul>" + "".join(f"<li>{e(i)}</li>" for i in b.items) + "</ul>")
        elif isinstance(b, _Table):
            head = "".join(f"<th>{e(h)}</th>" for h in b.header)
            body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in b.rows)
            out.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        else:
            src = b.file
            if embed:
                data = base64.b64encode((directory / b.file).read_bytes()).decode("ascii")
                src = f"data:image/png;base64,{data}"
            out.append(
                f'<figure><img src="{e(src)}" alt="{e(b.caption)}"><figcaption>{e(b.caption)}</figcaption></figure>'
            )
    out.append("</body></html>")
    return "\n".join(out) + "\n"


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
) -> Path:
    """Write the full uncertainty report into `directory` (created if needed).

    Files written: ``report.json`` (see :mod:`.json_report`), ``report.md``,
    ``report.html`` (self-contained: figures embedded as data URIs unless
    `embed_images` is False), and the figures ``histograms_<i>.png`` and
    ``position_error_<i>.png`` per test configuration (1-based), ``lcurve.png``,
    ``parameters.png`` and ``sweep_<name>.png`` per sweep.

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

    Returns
    -------
    Path
        The report directory.
    """
    warnings = merge_warnings(input_warnings, result.warnings)
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
    figures: list[_Image] = []
    for i in range(len(result.poses)):
        name = f"histograms_{i + 1}.png"
        plot_axis_histograms(result, out / name, pose=i)
        figures.append(
            _Image(
                name,
                f"Tool position per axis, test configuration {i + 1}, with mean, "
                "coverage intervals and the GUM normal pdf (cf. seed Fig. 10)",
            )
        )
        name = f"position_error_{i + 1}.png"
        plot_position_error(result, out / name, pose=i)
        figures.append(
            _Image(
                name,
                f"Position error |p − p̄|, test configuration {i + 1} (cf. seed Fig. 11)",
            )
        )
    plot_lcurve(result.calibration, out / "lcurve.png")
    figures.append(_Image("lcurve.png", "L-curve and GCV with the chosen λ"))
    if result.parameter_names:
        plot_parameter_distributions(result, out / "parameters.png")
        figures.append(
            _Image(
                "parameters.png",
                "Monte Carlo distributions of the identified parameter errors (cf. seed Fig. 5)",
            )
        )
    for sw in sweeps or ():
        name = f"sweep_{''.join(c if c.isalnum() else '_' for c in sw.name)}.png"
        plot_uncertainty_vs(
            sw.values,
            sw.standard_uncertainty,
            sw.xlabel,
            out / name,
            reference=sw.reference,
            log_x=sw.log_x,
        )
        figures.append(_Image(name, f"Standard uncertainty vs {sw.xlabel} (cf. seed Figs. 7-9)"))

    blocks: list[_Block] = [_Heading(1, title)]
    blocks += _summary(result)
    blocks += _table2(result)
    if budget:
        blocks += _budget(budget)
    blocks += _gum(result)
    blocks += _calibration(result.calibration, result)
    if sweeps:
        blocks.append(_Heading(2, "Sweeps"))
        for sw in sweeps:
            rows = [
                (f"{v:.4g}", *(_um(float(x)) for x in u), _um(float(np.linalg.norm(u))))
                for v, u in zip(sw.values, sw.standard_uncertainty)
            ]
            blocks.append(_Heading(3, f"{sw.name} ({sw.n_trials or '?'} trials per point)"))
            blocks.append(_table((sw.xlabel, "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm"), rows))
    blocks.append(_Heading(2, "Figures"))
    blocks += figures
    blocks += _settings(result, campaign_source, extra_settings, robot_name)
    blocks.append(_Heading(2, "Warnings"))
    blocks.append(_List(tuple(warnings)) if warnings else _Para("None."))

    (out / "report.md").write_text(_render_md(blocks), encoding="utf-8")
    (out / "report.html").write_text(_render_html(blocks, title, out, embed_images), encoding="utf-8")
    return out
