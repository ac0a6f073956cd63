"""Report of a section inspection: JSON (SI), Markdown, HTML, CSV and one histogram figure.

Values are SI inside and in the JSON (``units`` says which); the table, Markdown and CSV give
lengths in mm (estimates) and µm (uncertainties, profiles), angles in degrees. Every report
states, per parameter, the measured coverage of the interval it recommends and whether that
coverage is verified *for this cloud*: the cloud passed the residual check of its denoising
(:class:`~robocal_uncertainty.inspection.denoise.ResidualCheck`), and the interval's coverage was
verified (:mod:`~robocal_uncertainty.inspection.coverage_rule`: at least 92 %, not significantly
below 95 %, enough scans) by the stored studies of
:mod:`~robocal_uncertainty.inspection.stored_studies` or by a study run for the cloud itself. A
cloud the check flags is never stated verified, nor one outside the studies' scope. This module
computes no statistic: the verdicts come from ``inspection``; it lays them out as one
:mod:`~robocal_uncertainty.report.document_tree` rendered to Markdown and HTML.
The table's §8 column is the JCGM 101 §8 validation of the GUM interval by the Monte Carlo one
(whether the GUM framework reproduces the Monte Carlo interval), not a verdict on the part.
With repeated scans (``gum_with_repeatability``) every report also gives the reference paper's GUM budget
of the chord length (u1 MPE, u2 thermal, u3 repeatability, the other sources, u_c, k, U95).
``section.html`` is ``section.md`` as a self-contained page (the histograms embedded).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.inspection.bias_correction import BiasCorrection
from robocal_uncertainty.inspection.coverage_rule import BINOMIAL_LEVEL, COVERAGE_TOLERANCE, MIN_STUDY_SCANS
from robocal_uncertainty.inspection.coverage_study import ScenarioStudy
from robocal_uncertainty.inspection.denoise import ResidualCheck
from robocal_uncertainty.inspection.resolution import ENVELOPE_PARAMETERS, ENVELOPE_STREAM
from robocal_uncertainty.inspection.section import PARAMETER_NAMES, PARAMETER_UNITS
from robocal_uncertainty.inspection.section_mc import SectionUncertainty
from robocal_uncertainty.inspection.stored_studies import (
    COVERAGE_STUDY,
    FAMILY_CELLS,
    FAMILY_STUDY,
    FAMILY_STUDY_COMMAND,
    STUDY_NOMINAL_LENGTH,
    STUDY_POINTS,
    outside_study_scope,
    own_verdict,
    stated_coverage,
)
from robocal_uncertainty.report.document_tree import (
    Block,
    BulletList,
    Figure,
    Heading,
    Paragraph,
    Preformatted,
    Table,
    render_html,
    render_markdown,
    table,
)

__all__ = [
    "GUM_CHECK_LEGEND",
    "SECTION_REPORT_FILES",
    "SECTION_REPORT_FORMAT",
    "VERIFIED_OWN",
    "SectionReportFiles",
    "coverage_summary",
    "format_repeatability_budget",
    "format_section_table",
    "repeatability_budget",
    "section_report_blocks",
    "section_report_dict",
    "write_section_report",
]

SECTION_REPORT_FORMAT = "robocal_uncertainty/section_report/1"
"""``format`` field of ``section.json``."""

SECTION_REPORT_FILES = ("section.json", "section.md", "section.csv", "section_histograms.png", "section.html")
"""Files :func:`write_section_report` writes (always all of them, so ``--force`` leaves none stale)."""


_LABELS = {
    "max_thickness": "maximum thickness",
    "chord_length": "chord length",
    "axial_offset": "axial offset",
    "circumferential_offset": "circumferential offset",
    "twist_angle": "twist angle",
    "profile_leading_edge": "profile, leading edge",
    "profile_trailing_edge": "profile, trailing edge",
    "profile_pressure_side": "profile, pressure side",
    "profile_suction_side": "profile, suction side",
}


@dataclass(frozen=True)
class SectionReportFiles:
    """Paths written by :func:`write_section_report`."""

    json: Path
    markdown: Path
    csv: Path
    histograms: Path
    html: Path


def _display(name: str) -> tuple[str, float, str, float]:
    """(value unit, factor, uncertainty unit, factor) of a parameter for people."""
    if name == "twist_angle":
        return "deg", math.degrees(1.0), "mdeg", math.degrees(1.0) * 1e3
    if name.startswith("profile"):
        return "µm", 1e6, "µm", 1e6
    return "mm", 1e3, "µm", 1e6


def _decimals(u_scaled_to_value_unit: float) -> int:
    """Decimals that keep two significant digits of the uncertainty."""
    if not (math.isfinite(u_scaled_to_value_unit) and u_scaled_to_value_unit > 0):
        return 6
    return max(0, 1 - math.floor(math.log10(u_scaled_to_value_unit)))


def _rows(
    result: SectionUncertainty, corrections: tuple[BiasCorrection, ...], study: ScenarioStudy | None = None
) -> list[dict[str, Any]]:
    rows = []
    measured = result.parameters.as_array()
    cloud_check = result.check
    in_scope = outside_study_scope(result) is None
    for j, name in enumerate(PARAMETER_NAMES):
        mc = result.monte_carlo.outputs[j]
        gum = result.gum.outputs[j]
        check = result.validation[j]
        fix = corrections[j]
        rows.append(
            {
                "name": name,
                "unit": PARAMETER_UNITS[j],
                "measured": float(measured[j]),
                "mc_mean": mc.estimate,
                "u": mc.standard_uncertainty,
                "U": mc.expanded_uncertainty,
                "symmetric_interval": [mc.probabilistically_symmetric.low, mc.probabilistically_symmetric.high],
                "shortest_interval": [mc.shortest.low, mc.shortest.high],
                "gum_u": gum.standard_uncertainty,
                "gum_U": gum.expanded_uncertainty,
                "gum_interval": [gum.interval.low, gum.interval.high],
                "gum_validated": bool(check.validated),
                "gum_d_low": check.d_low,
                "gum_d_high": check.d_high,
                "gum_delta": check.delta,
                "bias": fix.bias,
                "bias_corrected_estimate": fix.estimate,
                "bias_corrected_interval": [fix.interval.low, fix.interval.high],
                "bias_correction_recommended": fix.recommended,
                "budget": {src: float(result.gum.sensitivities[j, k]) for k, src in enumerate(result.sources)},
                "coverage_study_jcgm101": COVERAGE_STUDY[name].jcgm101,
                "coverage_study_bias_corrected": COVERAGE_STUDY[name].reflected,
                "coverage_study_denoised": COVERAGE_STUDY[name].denoised,
                "coverage_family_study": {
                    family: {
                        "scans": study[name].scans,
                        "flagged": study[name].flagged,
                        "coverage_unflagged": study[name].coverage,
                        "u_binomial": study[name].u,
                        "p_value_holm": study[name].p_holm if math.isfinite(study[name].p_holm) else None,
                        "coverage_all": study[name].inside_all / study[name].scans if study[name].scans else None,
                    }
                    for family, study in FAMILY_STUDY.items()
                },
                "stated_interval": [fix.interval.low, fix.interval.high]
                if stated_coverage(name, result.method)[0] != "jcgm101"
                else [mc.probabilistically_symmetric.low, mc.probabilistically_symmetric.high],
                "stated_interval_kind": stated_coverage(name, result.method, cloud_check, in_scope=in_scope)[0],
                "coverage_measured": stated_coverage(name, result.method, cloud_check, in_scope=in_scope)[1],
                "coverage_verified": stated_coverage(name, result.method, cloud_check, in_scope=in_scope)[2],
            }
        )
        if study is not None:
            lowest, verified = own_verdict(name, result, study)
            rows[-1]["coverage_measured"] = lowest
            rows[-1]["coverage_verified"] = verified
            rows[-1]["coverage_verified_by"] = "this cloud's coverage study"
            rows[-1]["coverage_this_cloud_study"] = {
                family: {
                    "scans": cells[name].scans,
                    "flagged": cells[name].flagged,
                    "inside_unflagged": cells[name].inside,
                    "inside_all": cells[name].inside_all,
                    "coverage_unflagged": cells[name].coverage if math.isfinite(cells[name].coverage) else None,
                    "u_binomial": cells[name].u if math.isfinite(cells[name].u) else None,
                    "p_value_holm": cells[name].p_holm if math.isfinite(cells[name].p_holm) else None,
                    "verified": cells[name].consistent,
                }
                for family, cells in study.cells.items()
            }
    return rows


def section_report_dict(
    result: SectionUncertainty,
    corrections: tuple[BiasCorrection, ...],
    *,
    truth: NDArray[np.float64] | None = None,
    extra: dict[str, Any] | None = None,
    study: ScenarioStudy | None = None,
) -> dict[str, Any]:
    """The JSON content of a section report (SI units: m, rad); with `study`, the coverage
    verdict is that of the study run for this cloud (``coverage_study_this_cloud``)."""
    mc = result.monte_carlo
    inst = result.instrument
    rows = _rows(result, corrections, study)
    if truth is not None:
        for row, value in zip(rows, truth):
            row["truth"] = float(value)
    denoised = result.denoised
    return {
        "format": SECTION_REPORT_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "method": result.method,
        "denoise_half_width_m": None if denoised is None else denoised.half_width,
        "denoise_local_half_width_m": None
        if denoised is None
        else [float(denoised.local_half_width.min()), float(denoised.local_half_width.max())],
        "coverage_probability": mc.coverage_probability,
        "coverage_study_scope": {
            "points": STUDY_POINTS,
            "nominal_length_m": STUDY_NOMINAL_LENGTH,
            "instrument": "reference paper's CMM (cmm_reference_paper)",
            "this_cloud_points": result.n_points,
            "this_nominal_length_m": result.nominal_length if math.isfinite(result.nominal_length) else None,
            "outside_because": outside_study_scope(result),
        },
        "n_trials": mc.n_trials,
        "seed": mc.seed,
        "block_size": mc.block_size,
        "backend": None
        if result.backend is None
        else {"name": result.backend.name, "version": result.backend.version, "requested": result.backend.requested},
        "sources": list(result.sources),
        "instrument": {
            "name": inst.name,
            "mpe_a_m": inst.mpe_a,
            "mpe_k": inst.mpe_k,
            "thermal_expansion_half_width_per_degc": inst.thermal_half_width,
            "temperature_deviation_degc": inst.temperature_deviation,
            "probing_half_width_m": inst.probing_half_width,
            "algorithm_half_width_m": inst.algorithm_half_width,
        },
        "reference_point_m": result.reference.tolist(),
        "candidate_counts": list(result.candidate_counts),
        "parameters": rows,
        "residual_check": None if result.check is None else _check_dict(result.check),
        "roughness_envelope": _envelope_dict(result),
        "coverage_note": coverage_summary(result, study),
        "coverage_study_this_cloud": None if study is None else _study_dict(study),
        "gum_with_repeatability": repeatability_budget(result),
        **(extra or {}),
    }


def _backend_text(data: dict[str, Any]) -> str:
    """``numba 0.59.0 (auto)`` from the JSON's ``backend``, or ``not recorded``."""
    backend = data.get("backend")
    if not backend:
        return "not recorded"
    requested = "" if backend["requested"] == backend["name"] else f" ({backend['requested']})"
    return f"{backend['name']} {backend['version']}{requested}"


def _study_dict(study: ScenarioStudy) -> dict[str, Any]:
    """The cloud's own coverage study (SI): scenario, settings, time, counts, verdict."""
    inst = study.instrument
    return {
        "scenario": study.label,
        "points": study.n_points,
        "nominal_length_m": study.nominal_length,
        "instrument": {
            "name": inst.name,
            "mpe_a_m": inst.mpe_a,
            "mpe_k": inst.mpe_k,
            "thermal_expansion_half_width_per_degc": inst.thermal_half_width,
            "temperature_deviation_degc": inst.temperature_deviation,
            "probing_half_width_m": inst.probing_half_width,
            "algorithm_half_width_m": inst.algorithm_half_width,
        },
        "probe_vectors_from_cloud": study.probe_vectors,
        "form_rms_m": study.form_rms if math.isfinite(study.form_rms) else None,
        "form_scale": study.form_scale,
        "study_seed": study.root_seed,
        "scans_per_family": study.scans,
        "scans_total": study.total_scans,
        "trials_per_scan": study.trials,
        "trial_backend": None if study.backend is None else study.backend.describe(),
        "families": list(study.families),
        "elapsed_s": study.elapsed_s,
        "workers": study.workers,
        "counts": {
            family: {"scans": c[0], "flagged": c[1], "inside_unflagged": list(c[2]), "inside_all": list(c[3])}
            for family, c in study.counts.items()
        },
        "rule": (
            f"per parameter and family over the unflagged scans: at least {MIN_STUDY_SCANS} scans, coverage at "
            f"least {COVERAGE_TOLERANCE[0]:.0%}, exact one-sided binomial test of >= 95 % not rejected at "
            f"{BINOMIAL_LEVEL:.0%} after Holm over the study's cells"
        ),
        "verified": {name: study.verified(name) for name in PARAMETER_NAMES},
        "verified_all": study.verified_all,
    }


_SOURCE_LABELS = {
    "mpe": "u1 MPE",
    "thermal": "u2 thermal",
    "repeatability": "u3 repeatability",
    "probing": "probing",
    "algorithm": "algorithm",
}


def repeatability_budget(result: SectionUncertainty) -> dict[str, Any] | None:
    """The GUM budget with repeatability per parameter (SI), or None without repeated scans.

    ``contributions`` are the standard contributions [m, rad] of the instrument sources and of
    ``repeatability`` (the reference paper's u3: the standard deviation, ddof 1, of the repeated scans'
    values, a Type A input with ``n_scans - 1`` degrees of freedom); ``u_c`` their root sum of
    squares, ``k`` the Student t factor at the Welch-Satterthwaite ``effective_dof``, ``U`` = k u_c.
    """
    gum = result.gum_with_repeatability
    if gum is None:
        return None
    n_src = len(result.sources)
    dof = float(getattr(gum.input_distributions[n_src], "dof", math.nan))
    rows = []
    for j, name in enumerate(PARAMETER_NAMES):
        out = gum.outputs[j]
        contributions = {src: abs(float(gum.sensitivities[j, i])) for i, src in enumerate(result.sources)}
        contributions["repeatability"] = abs(float(gum.sensitivities[j, n_src + j]))
        rows.append(
            {
                "name": name,
                "unit": PARAMETER_UNITS[j],
                "estimate": out.estimate,
                "contributions": contributions,
                "u_c": out.standard_uncertainty,
                "effective_dof": out.effective_dof if math.isfinite(out.effective_dof) else None,
                "k": out.coverage_factor,
                "U": out.expanded_uncertainty,
            }
        )
    return {
        "n_scans": round(dof) + 1 if math.isfinite(dof) else None,
        "repeatability_dof": dof if math.isfinite(dof) else None,
        "coverage_probability": gum.coverage_probability,
        "parameters": rows,
    }


def _budget_order(contributions: dict[str, float]) -> list[str]:
    """The reference paper's order: u1 MPE, u2 thermal, u3 repeatability, then the other sources."""
    first = [s for s in ("mpe", "thermal", "repeatability") if s in contributions]
    return first + [s for s in contributions if s not in first]


def format_repeatability_budget(result: SectionUncertainty, name: str = "chord_length") -> str:
    """The reference paper's GUM budget table of one parameter (default the chord) with repeatability
    (u1 MPE, u2 thermal, u3 repeatability, the other sources, u_c, k, U95); "" without repeats."""
    budget = repeatability_budget(result)
    if budget is None:
        return ""
    j = PARAMETER_NAMES.index(name)
    row = budget["parameters"][j]
    vu, vf, uu, uf = _display(name)
    p = budget["coverage_probability"]
    nu = row["effective_dof"]
    lines = [
        f"GUM budget of the {_LABELS[name]} with repeatability ({budget['n_scans']} repeated scans, "
        f"u3 Type A with {budget['repeatability_dof']:.0f} degrees of freedom); standard contributions in {uu}:",
    ]
    for src in _budget_order(row["contributions"]):
        lines.append(f"  {_SOURCE_LABELS.get(src, src):18s} {row['contributions'][src] * uf:10.4f} {uu}")
    lines += [
        f"  {'u_c':18s} {row['u_c'] * uf:10.4f} {uu} (root sum of squares)",
        f"  {'k':18s} {row['k']:10.4f}    (Student t, {p:.0%}, "
        + (f"nu_eff = {nu:.1f})" if nu is not None else "nu_eff infinite)"),
        f"  {f'U{p * 100:.0f}':18s} {row['U'] * uf:10.4f} {uu} (k u_c)",
        f"  {_LABELS[name]} = {row['estimate'] * vf:.4f} {vu} +- {row['U'] * uf:.2f} {uu} "
        f"({p:.0%}, GUM with repeatability)",
    ]
    return "\n".join(lines)


def _envelope_dict(result: SectionUncertainty) -> dict[str, Any] | None:
    """The max/min parameters' roughness envelope (SI): the interval limits at the smooth and rough limits."""
    envelope = result.envelope
    if envelope is None:
        return None
    return {
        "n_draws": envelope.n_draws,
        "seed": envelope.seed,
        "spawn_key": [ENVELOPE_STREAM],
        "coverage_probability": envelope.coverage_probability,
        "profile_plateau_factor": envelope.plateau_factor,
        "parameters": {
            name: {
                "low_at_smooth_limit_m": float(envelope.measured[k] - envelope.smooth_high[k]),
                "high_at_rough_limit_m": float(envelope.measured[k] - envelope.rough_low[k]),
            }
            for k, name in enumerate(ENVELOPE_PARAMETERS)
        },
    }


def _check_dict(check: ResidualCheck) -> dict[str, Any]:
    return {
        "flagged": check.flagged,
        "p_value": check.p_value,
        "level": check.level,
        "statistic": check.statistic,
        "n_draws": check.n_draws,
        "seed": check.seed,
        "location_m": check.location,
        "extent_m": check.extent,
        "points": check.points,
        "local_half_width_m": check.half_width,
        "text": check.describe(),
    }


_DEMO_SCENARIO_TEXT = (
    "the demo scenario (Rotor 37 at the reference paper's size, 1 836 points, a 5 µm three-wave form error, "
    "the reference paper's offsets and twist and CMM; 200 simulated scans)"
)


def _family_text() -> str:
    parts = []
    for family, study in FAMILY_STUDY.items():
        first = next(iter(study.values()))
        worst = min(study.values(), key=lambda c: c.coverage if math.isfinite(c.coverage) else 2.0)
        name = next(n for n, c in study.items() if c is worst)
        parts.append(
            f"{family}: {first.scans} scans, {first.flagged} flagged, lowest coverage of the unflagged "
            f"{worst.coverage:.1%} +- {worst.u:.1%} ({_LABELS[name]})"
        )
    return "; ".join(parts)


VERIFIED_OWN = "verified for this part, layout and instrument"
"""The verdict of a parameter its cloud's own coverage study verifies."""


def _own_study_text(study: ScenarioStudy) -> str:
    parts = []
    for family, cells in study.cells.items():
        first = next(iter(cells.values()))
        finite = [c for c in cells.values() if math.isfinite(c.coverage)]
        if finite:
            worst = min(finite, key=lambda c: c.coverage)
            name = next(n for n, c in cells.items() if c is worst)
            low = f"lowest coverage of the unflagged {worst.coverage:.1%} +- {worst.u:.1%} ({_LABELS[name]})"
        else:
            low = "every scan flagged"
        parts.append(f"{family}: {first.scans} scans, {first.flagged} flagged, {low}")
    return "; ".join(parts)


def _own_summary(result: SectionUncertainty, study: ScenarioStudy, rule: str) -> str:
    check = result.check
    scale = (
        f"form amplitudes x {study.form_scale:.2f} (the cloud's denoised form RMS "
        f"{study.form_rms * 1e6:.2f} µm, the stored study's base form 3.54 µm)"
        if math.isfinite(study.form_rms)
        else "the stored amplitudes"
    )
    head = (
        f"Coverage study of this cloud: {study.scans} simulated scans per family ({', '.join(study.families)}; "
        f"{study.total_scans} in all, {study.trials} trials each, study seed {study.root_seed}, "
        f"{study.elapsed_s:.0f} s) of {study.label}: its nominal, its {study.n_points}-point layout"
        + (" and probe vectors" if study.probe_vectors else "")
        + f", its offsets and twist, {scale}; method 'denoised' on each, coverage {rule}: {_own_study_text(study)}."
    )
    if check is None:
        return head + " This cloud was not checked: no stated interval is verified for it."
    if check.flagged:
        return (
            head + f" This cloud: {check.describe()}. Its intervals are NOT verified for this cloud: the study "
            "holds for parts whose form the denoising follows."
        )
    short = [f for f, c in study.counts.items() if c[0] - c[1] < MIN_STUDY_SCANS]
    failing = [_LABELS[n] for n in PARAMETER_NAMES if not study.verified(n)]
    if not failing:
        return head + f" This cloud: {check.describe()}. Every stated interval is {VERIFIED_OWN}."
    why = (
        f" (families with fewer than {MIN_STUDY_SCANS} unflagged scans cannot verify anything: {', '.join(short)})"
        if short
        else ""
    )
    return (
        head
        + f" This cloud: {check.describe()}. NOT verified for this part, layout and instrument{why}: "
        + ", ".join(failing)
        + "."
    )


def coverage_summary(result: SectionUncertainty, study: ScenarioStudy | None = None) -> str:
    """What the residual check of this cloud and the measured coverage say about its intervals
    (one paragraph); with `study`, the verdict of the coverage study run for this cloud."""
    method = result.method
    check = result.check
    lo = COVERAGE_TOLERANCE[0]
    if study is not None:
        own_rule = (
            f"at least {lo:.0%} and not significantly below 95 % (exact one-sided binomial test at "
            f"{BINOMIAL_LEVEL:.0%}, Holm-adjusted over the study's cells, at least {MIN_STUDY_SCANS} unflagged "
            "scans per family)"
        )
        return _own_summary(result, study, own_rule)
    rule = (
        f"at least {lo:.0%} and not significantly below 95 % (exact one-sided binomial test at "
        f"{BINOMIAL_LEVEL:.0%}, at least {MIN_STUDY_SCANS} scans) over {_DEMO_SCENARIO_TEXT} and over the unflagged "
        f"scans of every scenario family (there the test is Holm-adjusted over the study's {FAMILY_CELLS} cells)"
    )
    denoised = ", ".join(f"{_LABELS[n]} {v.denoised:.1%}" for n, v in COVERAGE_STUDY.items())
    paper = ", ".join(f"{_LABELS[n]} {v.jcgm101:.1%}" for n, v in COVERAGE_STUDY.items())
    reflected = ", ".join(f"{_LABELS[n]} {v.reflected:.1%}" for n, v in COVERAGE_STUDY.items())
    scope = outside_study_scope(result)
    failing = [_LABELS[n] for n in COVERAGE_STUDY if not stated_coverage(n, method, check)[2]]
    if check is None:
        cloud = "This cloud was not checked: no stated interval is verified for it."
    elif scope is not None:
        cloud = (
            f"This cloud: {check.describe()}. Its intervals are NOT verified for this cloud: it is outside "
            f"the scope of the coverage studies below ({scope}; the studies simulate {STUDY_POINTS}-point "
            "scans of the Rotor 37 section at the reference paper's size on the reference paper's CMM), whose "
            "coverage is not carried to another point density, blade or instrument; "
            "`section CLOUD --coverage-study N` runs the study for this cloud's own part, layout and instrument."
        )
    elif check.flagged:
        cloud = (
            f"This cloud: {check.describe()}. Its intervals are NOT verified for this cloud: the coverage "
            "studies below hold for parts whose form the denoising follows, and the thickness and profile "
            "intervals of a part with a feature it does not follow can miss the truth."
        )
    elif not failing:
        cloud = f"This cloud: {check.describe()}. Every stated interval is coverage-verified for it (coverage {rule})."
    else:
        cloud = f"This cloud: {check.describe()}. NOT coverage-verified (coverage {rule}): " + ", ".join(failing) + "."
    families = (
        f" Scenario families (method 'denoised', {FAMILY_STUDY_COMMAND}; smooth forms of 2-13 waves, bumps and "
        f"dents of 1-10 µm over 1-20 mm on the sides and at the edges, edge erosion): {_family_text()}."
    )
    background = (
        " The max/min-defined parameters (maximum thickness, chord, profiles) are biased upward by "
        "the measurement noise, and the reference paper's Monte Carlo, which perturbs the already noisy measured "
        f"cloud, adds that noise again: its 95 % JCGM 101 intervals under-cover. Over {_DEMO_SCENARIO_TEXT} "
        f"they cover the truth in: {paper}; reflected about the measured value (bias-corrected) in: {reflected}."
    )
    if method == "denoised":
        return (
            cloud + " Method 'denoised': the error of the measured value is sampled around a denoised cloud "
            "(normal deviations smoothed along the section by local quadratics, the widest window chosen by "
            "Mallows' Cp with the instrument's noise variance and narrowed per point where narrower windows "
            "disagree, intersection of confidence intervals) and the interval for the true value is "
            "[f(y) - q97.5, f(y) - q2.5] of that error; the estimate is the measured value f(y), the bias the "
            "mean error. The interval of a max/min parameter (thickness, chord, profiles) is widened to the "
            "union with the same interval at the smoothest "
            "form the scan supports (one Cp window) and at the roughest (the measured deviations): a local "
            "feature the noise hides from the residual check can make the true form anywhere between, and "
            "its noise bias with it (asymmetric, wider than the Monte Carlo interval; it over-covers a "
            f"smooth part). Over {_DEMO_SCENARIO_TEXT} its 95 % intervals cover the truth in: {denoised}."
            + families
            + background
        )
    return (
        cloud
        + " Method 'perturbed':"
        + background
        + " Offsets and twist are well calibrated. Thickness and chord under-cover even corrected; the "
        "profile intervals do not cover the true form deviation: read the profile values as an upper bound "
        f"that includes the instrument noise range, or use method 'denoised' (coverage {denoised})." + families
    )


def _coverage_cell(name: str, result: SectionUncertainty, study: ScenarioStudy | None = None) -> str:
    if study is not None:
        if result.check is None or result.check.flagged:
            return "not verified for this cloud"
        lowest, verified = own_verdict(name, result, study)
        shown = f"{lowest:.1%}" if math.isfinite(lowest) else "-"
        return f"{shown} {VERIFIED_OWN}" if verified else f"{shown} NOT VERIFIED for this part (own study)"
    _, value, verified = stated_coverage(name, result.method, result.check)
    if result.check is None or result.check.flagged or outside_study_scope(result) is not None:
        return "not verified for this cloud"
    if not verified:
        return f"{value:.1%} NOT VERIFIED"
    # value is the lowest of the studies: above 98 % every study over-covers.
    return f"{value:.1%} verified" + (" (over-covers)" if value > COVERAGE_TOLERANCE[1] else "")


GUM_CHECK_LEGEND = (
    "GUM=MC (JCGM 101 §8): agree when the GUM interval y +- U matches the Monte Carlo interval within the "
    "numerical tolerance (GUM framework validated for this parameter), differ when not (use the Monte Carlo "
    "interval); it is not a pass/fail of the part or the measurement."
)
"""Legend of the table's §8 column."""


def format_section_table(
    result: SectionUncertainty,
    corrections: tuple[BiasCorrection, ...],
    *,
    truth: NDArray[np.float64] | None = None,
    study: ScenarioStudy | None = None,
) -> str:
    """Console table in the reference paper's layout: value, u, 95 % interval, GUM u, the JCGM 101 §8 GUM
    validation (``agree``/``differ``), and the measured coverage of the stated interval (``NOT
    VERIFIED`` outside the tolerance, ``not verified for this cloud`` when the residual check
    flagged it); then the §8 legend and the residual check's line.

    Method ``perturbed``: the JCGM 101 interval of the perturbed measured cloud and the bias-corrected
    (reflected) one. Method ``denoised``: the estimated bias and the Monte Carlo interval for the
    measurand (u is the standard deviation of the error Δ).
    """
    p = result.monte_carlo.coverage_probability
    denoised = result.method == "denoised"
    if denoised:
        head = (
            f"{'parameter':24s} {'measured':>13s} {'bias':>10s} {'u':>10s} {'U':>10s} "
            f"{f'{p:.0%} interval (denoised MC)':34s} {'GUM u':>10s} GUM=MC(§8) coverage"
        )
    else:
        head = (
            f"{'parameter':24s} {'measured':>13s} {'u':>10s} {'U':>10s} {f'{p:.0%} interval (JCGM 101)':34s} "
            f"{'bias-corrected interval':30s} {'GUM u':>10s} GUM=MC(§8) coverage"
        )
    lines = [head, "-" * len(head)]
    for j, name in enumerate(PARAMETER_NAMES):
        vu, vf, uu, uf = _display(name)
        mc = result.monte_carlo.outputs[j]
        fix = corrections[j]
        digits = _decimals(mc.standard_uncertainty * vf)
        iv = mc.probabilistically_symmetric
        stated = fix.interval if stated_coverage(name, result.method)[0] != "jcgm101" else iv
        verdict = f"{'agree' if result.validation[j].validated else 'differ':10s}"
        value = f"{_LABELS[name]:24s} {fix.measured * vf:>9.{digits}f} {vu:3s} "
        spread = f"{mc.standard_uncertainty * uf:>5.2f} {uu:4s} {mc.expanded_uncertainty * uf:>5.2f} {uu:4s} "
        coverage = _coverage_cell(name, result, study)
        gum = f"{result.gum.outputs[j].standard_uncertainty * uf:>5.2f} {uu:4s} {verdict} {coverage}"
        if denoised:
            interval = f"[{stated.low * vf:.{digits}f}, {stated.high * vf:.{digits}f}] {vu}"
            lines.append(f"{value}{fix.bias * uf:>5.2f} {uu:4s} {spread}{interval:34s} {gum}")
        else:
            interval = f"[{iv.low * vf:.{digits}f}, {iv.high * vf:.{digits}f}] {vu}"
            fixed = f"[{fix.interval.low * vf:.{digits}f}, {fix.interval.high * vf:.{digits}f}]"
            lines.append(f"{value}{spread}{interval:34s} {fixed:30s} {gum}")
        if truth is not None:
            t = float(truth[j])
            if denoised:
                inside = "inside" if stated.contains(t) else "OUTSIDE"
                lines.append(f"{'':24s} truth {t * vf:.{digits}f} {vu}: {inside} the interval")
            else:
                inside = "inside" if iv.contains(t) else "OUTSIDE"
                inside_fix = "inside" if fix.interval.contains(t) else "OUTSIDE"
                lines.append(
                    f"{'':24s} truth {t * vf:.{digits}f} {vu}: {inside} the JCGM 101 interval, "
                    f"{inside_fix} the bias-corrected one"
                )
    lines.append(GUM_CHECK_LEGEND)
    if result.check is not None:
        lines.append(f"This cloud: {result.check.describe()}.")
    return "\n".join(lines)


def section_report_blocks(data: dict[str, Any], console_table: str) -> list[Block]:
    """``section.md`` and ``section.html`` as one document tree, from the JSON content `data`
    (:func:`section_report_dict`) and the console table `console_table` (:func:`format_section_table`)."""
    denoise = (
        f" (denoising window half-width {data['denoise_half_width_m'] * 1e3:.1f} mm by Cp, "
        f"{data['denoise_local_half_width_m'][0] * 1e3:.1f}-{data['denoise_local_half_width_m'][1] * 1e3:.1f} mm "
        "along the contour)"
        if data.get("denoise_half_width_m") is not None
        else ""
    )
    blocks: list[Block] = [
        Heading(1, "Section inspection: parameters and their uncertainty"),
        BulletList(
            (
                f"cloud: {data.get('cloud', '')}",
                f"nominal: {data.get('nominal', '')}",
                f"instrument: {data['instrument']['name']} ({data.get('instrument_file', '')})",
                f"trials: {data['n_trials']}, random seed: {data['seed']}, block size {data['block_size']}, "
                f"coverage probability {data['coverage_probability']}; trial kernels: {_backend_text(data)}",
                f"sources: {', '.join(data['sources'])}; MPE/thermal reference point "
                f"({', '.join(f'{v * 1e3:.3f}' for v in data['reference_point_m'])}) mm",
                f"method: {data['method']}{denoise}",
            )
        ),
        Heading(2, "Results"),
        Paragraph(
            "Estimates in mm (twist in degrees, profiles in µm), uncertainties in µm (twist in millidegrees). "
            "GUM=MC(§8): the JCGM 101 §8 validation of the GUM interval by the Monte Carlo one (whether the GUM "
            "framework reproduces it), not a verdict on the part."
        ),
        Preformatted(console_table),
        Paragraph("Shortest 95 % intervals, and the GUM interval:"),
        _interval_table(data),
        Heading(2, "GUM budget per source (standard contributions)"),
        _budget_table(data),
        Heading(2, "Coverage of the intervals: this cloud's check and the simulated studies"),
        Paragraph(data["coverage_note"]),
        Paragraph("Demo scenario (200 simulated scans of one part):"),
        _demo_study_table(data),
        Paragraph(
            f"Scenario families (method denoised; `{FAMILY_STUDY_COMMAND}`): coverage over the scans the residual "
            "check did not flag, ± its binomial standard uncertainty; flagged scans per family in the header."
        ),
        _family_study_table(),
    ]
    own = data.get("coverage_study_this_cloud")
    if own is not None:
        blocks += _own_study_blocks(own)
    repeat = data.get("gum_with_repeatability")
    if repeat is not None:
        blocks += _repeatability_blocks(repeat, data.get("repeat_scans"))
    blocks += [
        Heading(2, "Histograms"),
        Figure(
            "section_histograms.png",
            "Monte Carlo values of the nine parameters about the measured value; dashed: the stated 95 % interval",
            caption_below=False,
        ),
    ]
    return blocks


def _interval_table(data: dict[str, Any]) -> Table:
    rows = []
    for row in data["parameters"]:
        vu, vf, uu, uf = _display(row["name"])
        digits = _decimals(row["u"] * vf)
        s, g = row["shortest_interval"], row["gum_interval"]
        rows.append(
            (
                _LABELS[row["name"]],
                f"[{s[0] * vf:.{digits}f}, {s[1] * vf:.{digits}f}] {vu}",
                f"[{g[0] * vf:.{digits}f}, {g[1] * vf:.{digits}f}] {vu}",
                f"{row['gum_d_low'] * uf:.3f} {uu}",
                f"{row['gum_d_high'] * uf:.3f} {uu}",
                f"{row['gum_delta'] * uf:.3f} {uu}",
            )
        )
    return table(("parameter", "shortest interval", "GUM interval", "d_low", "d_high", "δ"), rows)


def _budget_table(data: dict[str, Any]) -> Table:
    sources = data["sources"]
    rows = []
    for row in data["parameters"]:
        _, _, uu, uf = _display(row["name"])
        rows.append(
            (
                f"{_LABELS[row['name']]} ({uu})",
                *(f"{row['budget'][s] * uf:.3f}" for s in sources),
                f"{row['gum_u'] * uf:.3f}",
            )
        )
    return table(("parameter", *sources, "combined"), rows)


def _demo_study_table(data: dict[str, Any]) -> Table:
    rows = []
    for row in data["parameters"]:
        study = COVERAGE_STUDY[row["name"]]
        flag = "verified" if row["coverage_verified"] else "NOT VERIFIED"
        rows.append(
            (
                _LABELS[row["name"]],
                f"{study.jcgm101:.1%}",
                f"{study.reflected:.1%}",
                f"{study.denoised:.1%}",
                f"{row['stated_interval_kind']} {row['coverage_measured']:.1%} {flag}",
            )
        )
    header = (
        "parameter",
        "perturbed: JCGM 101 interval",
        "perturbed: bias-corrected (reflected)",
        "denoised",
        "this report",
    )
    return table(header, rows)


def _family_study_table() -> Table:
    header = ["parameter"]
    for family, study in FAMILY_STUDY.items():
        first = next(iter(study.values()))
        header.append(f"{family} ({first.flagged}/{first.scans} flagged)")
    rows = [
        (
            _LABELS[name],
            *(
                f"{study[name].coverage:.1%} ± {study[name].u:.1%}" if study[name].scans > study[name].flagged else "-"
                for study in FAMILY_STUDY.values()
            ),
        )
        for name in PARAMETER_NAMES
    ]
    return table(header, rows)


def _own_study_blocks(own: dict[str, Any]) -> list[Block]:
    """The cloud's own coverage study: settings, then coverage per parameter and family and the verdict."""
    inst = own["instrument"]
    scale = (
        f"form amplitudes x {own['form_scale']:.2f} (denoised form RMS {own['form_rms_m'] * 1e6:.2f} µm)"
        if own["form_rms_m"] is not None
        else "stored amplitudes"
    )
    families = own["families"]
    settings = BulletList(
        (
            f"scenario: {own['scenario']}",
            f"{own['points']} points per scan (the cloud's layout"
            + (", its probe vectors" if own["probe_vectors_from_cloud"] else "")
            + f"), nominal contour {own['nominal_length_m'] * 1e3:.1f} mm, {scale}",
            f"instrument {inst['name']}: MPE ({inst['mpe_a_m'] * 1e6:.2f} + L/{inst['mpe_k']:g}) µm, probing "
            f"{inst['probing_half_width_m'] * 1e6:.2f} µm, thermal {inst['thermal_expansion_half_width_per_degc']:g} "
            f"/°C x {inst['temperature_deviation_degc']:g} °C",
            f"{own['scans_per_family']} scans per family ({', '.join(families)}), {own['scans_total']} in all, "
            f"{own['trials_per_scan']} trials each, study seed {own['study_seed']}, {own['elapsed_s']:.0f} s on "
            f"{own['workers']} worker(s)"
            + (f", trial kernels {own['trial_backend']}" if own.get("trial_backend") else ""),
            f"rule: {own['rule']}",
        )
    )
    rows = []
    for j, name in enumerate(PARAMETER_NAMES):
        cells = []
        for f in families:
            c = own["counts"][f]
            kept = c["scans"] - c["flagged"]
            cells.append(
                f"{c['inside_unflagged'][j] / kept:.1%} ± {math.sqrt(0.95 * 0.05 / kept):.1%}" if kept else "-"
            )
        verdict = VERIFIED_OWN if own["verified"][name] else "NOT VERIFIED"
        rows.append((_LABELS[name], *cells, verdict))
    header = (
        "parameter",
        *(f"{f} ({own['counts'][f]['flagged']}/{own['counts'][f]['scans']} flagged)" for f in families),
        "study verdict",
    )
    return [
        Heading(2, "Coverage study of this cloud (its part, layout and instrument)"),
        settings,
        Paragraph(
            "Coverage over the scans the residual check did not flag, ± its binomial standard uncertainty "
            "(flagged scans per family in the header); verdict per parameter over every family:"
        ),
        table(header, rows),
    ]


def _repeatability_blocks(repeat: dict[str, Any], files: list[str] | None) -> list[Block]:
    chord = repeat["parameters"][PARAMETER_NAMES.index("chord_length")]
    p = repeat["coverage_probability"]
    u_label = f"U{p * 100:.0f}"
    nu = chord["effective_dof"]
    chord_rows = [
        (_SOURCE_LABELS.get(s, s), f"{chord['contributions'][s] * 1e6:.4f} µm")
        for s in _budget_order(chord["contributions"])
    ]
    chord_rows += [
        ("u_c", f"{chord['u_c'] * 1e6:.4f} µm"),
        ("k", f"{chord['k']:.4f} (ν_eff {'infinite' if nu is None else f'{nu:.1f}'})"),
        (u_label, f"{chord['U'] * 1e6:.4f} µm"),
    ]
    rows = []
    for row in repeat["parameters"]:
        _, _, uu, uf = _display(row["name"])
        nu = row["effective_dof"]
        rows.append(
            (
                _LABELS[row["name"]],
                f"{row['contributions']['repeatability'] * uf:.4f} {uu}",
                f"{row['u_c'] * uf:.4f} {uu}",
                "inf" if nu is None else f"{nu:.1f}",
                f"{row['k']:.3f}",
                f"{row['U'] * uf:.4f} {uu}",
            )
        )
    return [
        Heading(2, "GUM budget with repeatability (reference paper's table)"),
        Paragraph(
            f"Chord length, {repeat['n_scans']} repeated scans"
            + (f" ({', '.join(files)})" if files else "")
            + f": u3 is the standard deviation (ddof 1) of their chord lengths, a Type A input with "
            f"{repeat['repeatability_dof']:.0f} degrees of freedom; u_c the root sum of squares, k the Student t "
            f"factor at ν_eff (Welch-Satterthwaite), {u_label} = k u_c."
        ),
        table(("source", "standard contribution"), chord_rows),
        Paragraph("Every parameter with repeatability:"),
        table(("parameter", "u3 repeatability", "u_c", "ν_eff", "k", u_label), rows),
    ]


def _stated_interval(name: str, result: SectionUncertainty, fix: BiasCorrection) -> Any:
    """The interval the report states for `name`: the bias-corrected one (for ``denoised``, widened
    to the roughness envelope), or the JCGM 101 one for the offsets and twist under ``perturbed``."""
    j = PARAMETER_NAMES.index(name)
    if stated_coverage(name, result.method)[0] == "jcgm101":
        return result.monte_carlo.outputs[j].probabilistically_symmetric
    return fix.interval


def _plot(result: SectionUncertainty, corrections: tuple[BiasCorrection, ...], path: Path) -> None:
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 3, figsize=(13, 10))
    for j, (name, ax) in enumerate(zip(PARAMETER_NAMES, axes.ravel())):
        vu, vf, uu, uf = _display(name)
        output = result.monte_carlo.outputs[j]
        hist = output.histogram
        y = corrections[j].measured
        ax.stairs(hist.counts, (hist.edges - y) * uf, fill=True, alpha=0.6)
        # The interval the table states (widened to the roughness envelope, clipped at 0 for the
        # max/min parameters), not the Monte Carlo-only one.
        iv = _stated_interval(name, result, corrections[j])
        for x in (iv.low, iv.high):
            ax.axvline((x - y) * uf, color="C1", linestyle="--", linewidth=1)
        ax.axvline(0.0, color="k", linewidth=1)
        ax.set_title(f"{_LABELS[name]}", fontsize=10)
        digits = _decimals(output.standard_uncertainty * vf)
        ax.set_xlabel(f"{uu} from the measured {y * vf:.{digits}f} {vu}")
        ax.set_ylabel("trials per bin")
    what = "values f(y) - Δ of the measurand" if result.method == "denoised" else "values"
    fig.suptitle(
        f"Monte Carlo {what} ({result.monte_carlo.n_trials} trials) about the measured value (black); "
        f"dashed: the stated {result.monte_carlo.coverage_probability:.0%} interval"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_section_report(
    result: SectionUncertainty,
    corrections: tuple[BiasCorrection, ...],
    out_dir: str | Path,
    *,
    truth: NDArray[np.float64] | None = None,
    extra: dict[str, Any] | None = None,
    study: ScenarioStudy | None = None,
) -> SectionReportFiles:
    """Write ``section.json``, ``section.md``, ``section.csv``, ``section_histograms.png`` and
    ``section.html`` (``section.md`` as a self-contained page, the histograms embedded)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = section_report_dict(result, corrections, truth=truth, extra=extra, study=study)
    files = SectionReportFiles(*(out / name for name in SECTION_REPORT_FILES))
    files.json.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    table = format_section_table(result, corrections, truth=truth, study=study)
    blocks = section_report_blocks(data, table)
    files.markdown.write_text(render_markdown(blocks), encoding="utf-8")
    with files.csv.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(
            [
                "parameter",
                "unit",
                "measured",
                "mc_mean",
                "u",
                "U",
                "symmetric_low",
                "symmetric_high",
                "shortest_low",
                "shortest_high",
                "gum_u",
                "gum_validated",
                "bias_corrected_low",
                "bias_corrected_high",
                "coverage_measured",
                "coverage_verified",
            ]
        )
        for row in data["parameters"]:
            writer.writerow(
                [
                    row["name"],
                    row["unit"],
                    row["measured"],
                    row["mc_mean"],
                    row["u"],
                    row["U"],
                    *row["symmetric_interval"],
                    *row["shortest_interval"],
                    row["gum_u"],
                    row["gum_validated"],
                    *row["bias_corrected_interval"],
                    row["coverage_measured"],
                    row["coverage_verified"],
                ]
            )
    _plot(result, corrections, files.histograms)
    files.html.write_text(render_html(blocks, "Section inspection report", out), encoding="utf-8")
    return files
