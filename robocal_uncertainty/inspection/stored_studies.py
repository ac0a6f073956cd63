"""The stored coverage studies of the section method and the verdict they give a cloud.

A section report states, per parameter, the measured coverage of the interval it recommends
and whether that coverage is verified for the cloud. Those numbers come from two stored studies
(the demo scenario, :data:`COVERAGE_STUDY`; the scenario families, :data:`FAMILY_STUDY`) or from
a study run for the cloud itself (:class:`~robocal_uncertainty.inspection.coverage_study.ScenarioStudy`),
judged by one rule (:mod:`.coverage_rule`). The verdict is computed here, beside the studies, so
the report only renders it; a cloud outside the stored studies' scope (:func:`outside_study_scope`)
is never stated verified by them.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

from robocal_uncertainty.core.instruments.cmm import CmmInstrument
from robocal_uncertainty.inspection.coverage_rule import FamilyCounts, FamilyCoverage, coverage_verified, family_cells
from robocal_uncertainty.inspection.coverage_study import ScenarioStudy
from robocal_uncertainty.inspection.denoise import ResidualCheck
from robocal_uncertainty.inspection.section import PARAMETER_NAMES
from robocal_uncertainty.inspection.section_mc import SectionUncertainty

__all__ = [
    "COVERAGE_STUDY",
    "DEMO_SCANS",
    "FAMILY_CELLS",
    "FAMILY_COUNTS",
    "FAMILY_STUDY",
    "FAMILY_STUDY_COMMAND",
    "LINEAR_PARAMETERS",
    "STUDY_NOMINAL_LENGTH",
    "STUDY_POINTS",
    "Coverage",
    "family_coverage",
    "outside_study_scope",
    "own_verdict",
    "stated_coverage",
]


class Coverage(NamedTuple):
    """Measured coverage of the 95 % intervals of one parameter, per interval kind."""

    jcgm101: float
    """Method ``perturbed``: the JCGM 101 interval of the measured cloud perturbed."""
    reflected: float
    """Method ``perturbed``: that interval reflected about the measured value (bias-corrected)."""
    denoised: float
    """Method ``denoised``: the interval of f(y) - Δ, Δ sampled around the denoised cloud."""


COVERAGE_STUDY: dict[str, Coverage] = {
    "max_thickness": Coverage(0.72, 0.89, 0.96),
    "chord_length": Coverage(0.895, 0.905, 0.94),
    "axial_offset": Coverage(0.935, 0.935, 0.935),
    "circumferential_offset": Coverage(0.945, 0.945, 0.945),
    "twist_angle": Coverage(0.945, 0.935, 0.935),
    "profile_leading_edge": Coverage(0.0, 0.73, 0.965),
    "profile_trailing_edge": Coverage(0.0, 0.585, 0.975),
    "profile_pressure_side": Coverage(0.0, 0.075, 0.975),
    "profile_suction_side": Coverage(0.0, 0.13, 0.96),
}
"""Measured coverage of the 95 % intervals over 200 simulated 1 836-point scans of the demo
section with a known truth (one instrument-noise draw per scan; slow test
``test/inspection/test_inspection_section_mc.py::test_coverage_over_200_simulated_scans``).
One scan in 200 is 0.5 %; the binomial standard error at 95 % is 1.5 %."""

DEMO_SCANS = 200
"""Scans of the demo scenario's study (:data:`COVERAGE_STUDY`)."""


FAMILY_STUDY_COMMAND = "python benchmarks/bench_section_coverage.py --scans 600 --workers 2"
"""The command whose output :data:`FAMILY_STUDY` holds."""

FAMILY_COUNTS: dict[str, FamilyCounts] = {
    # family: (scans, flagged, inside per parameter among the unflagged, inside among all)
    "smooth": (600, 30, (550, 544, 538, 540, 534, 561, 553, 561, 554), (578, 573, 567, 569, 563, 591, 582, 591, 581)),
    "side": (600, 93, (481, 474, 481, 482, 481, 496, 498, 487, 493), (568, 562, 570, 573, 571, 587, 591, 578, 581)),
    "edge": (600, 122, (460, 453, 457, 451, 455, 473, 465, 459, 462), (577, 569, 573, 568, 574, 593, 584, 580, 579)),
    "erosion": (600, 201, (384, 377, 375, 378, 381, 394, 384, 382, 382), (576, 567, 567, 566, 574, 591, 581, 572, 573)),
}


FAMILY_STUDY: dict[str, dict[str, FamilyCoverage]] = family_cells(FAMILY_COUNTS, PARAMETER_NAMES)
"""Coverage of method ``denoised`` per scenario family and parameter
(:mod:`~robocal_uncertainty.inspection.coverage_study`: smooth forms of 2-13 waves; bumps and
dents of 1-10 µm over 1-20 mm on the sides, at the edges; edge erosion), as printed by
:data:`FAMILY_STUDY_COMMAND`. A cell is verified (:attr:`FamilyCoverage.consistent`) at its
Holm-adjusted p-value: with 36 cells, a per-cell 5 % test would call some cell significantly
below 95 % with probability about 0.8 even if every interval covered exactly 95 %."""

STUDY_POINTS = 1836
"""Points per scan in every coverage study (the reference paper's count, denser at the edges)."""

STUDY_NOMINAL_LENGTH = 0.80977
"""Contour length [m] of the studies' nominal: Rotor 37 surface 2 at the reference paper's size (x7.14)."""

STUDY_POINT_TOLERANCE = 0.10
STUDY_LENGTH_TOLERANCE = 0.01


def outside_study_scope(result: SectionUncertainty) -> str | None:
    """Why the coverage studies do not speak for this cloud, or None when they do.

    Every study simulates the same kind of scan: :data:`STUDY_POINTS` points (± 10 % accepted)
    of a section whose nominal contour is :data:`STUDY_NOMINAL_LENGTH` long (± 1 %), measured by
    the reference paper's CMM (:class:`~robocal_uncertainty.core.instruments.cmm.CmmInstrument` defaults).
    The denoising windows, the residual check's power and the roughness envelope all depend on
    the point spacing, the contour and the noise, so a measured coverage is not carried to
    another point density, blade or instrument: outside that scope no interval is stated
    verified. The tolerances say what is taken as the same scan; they are not a measured range
    of validity.
    """
    reasons = []
    if abs(result.n_points - STUDY_POINTS) > STUDY_POINT_TOLERANCE * STUDY_POINTS:
        reasons.append(f"{result.n_points} points, the studies {STUDY_POINTS}")
    if not abs(result.nominal_length - STUDY_NOMINAL_LENGTH) <= STUDY_LENGTH_TOLERANCE * STUDY_NOMINAL_LENGTH:
        reasons.append(
            f"a nominal contour of {result.nominal_length * 1e3:.1f} mm, the studies' Rotor 37 section "
            f"{STUDY_NOMINAL_LENGTH * 1e3:.1f} mm"
        )
    paper = CmmInstrument()
    numeric = [f.name for f in dataclasses.fields(CmmInstrument) if f.name != "name"]
    if not all(math.isclose(getattr(result.instrument, n), getattr(paper, n), rel_tol=1e-9) for n in numeric):
        reasons.append("an instrument other than the reference paper's CMM the studies simulate")
    return "; ".join(reasons) or None


FAMILY_CELLS = sum(1 for study in FAMILY_STUDY.values() for c in study.values() if c.scans > c.flagged)
"""Cells of :data:`FAMILY_STUDY` with a test (some unflagged scans): the Holm adjustment's count."""

LINEAR_PARAMETERS = ("axial_offset", "circumferential_offset", "twist_angle")
"""Parameters linear in the errors: methods ``perturbed`` and ``denoised`` state the same interval."""


def family_coverage(name: str) -> tuple[float, bool]:
    """Lowest coverage over the scenario families' unflagged scans, and whether every family is consistent."""
    rows = [study[name] for study in FAMILY_STUDY.values() if study[name].scans > study[name].flagged]
    if not rows:
        return math.nan, False
    return min(r.coverage for r in rows), all(r.consistent for r in rows)


def stated_coverage(
    name: str, method: str, check: ResidualCheck | None = None, *, in_scope: bool = True
) -> tuple[str, float, bool]:
    """The interval a report recommends for parameter `name` under `method`, its measured
    coverage and whether that is verified for the cloud whose residual check is `check`.

    Returns
    -------
    tuple
        ``(kind, coverage, verified)``: kind ``jcgm101`` (method ``perturbed``, offsets and twist),
        ``reflected`` (method ``perturbed``, the max/min parameters) or ``denoised``; coverage the
        lowest of the demo scenario's study and (``jcgm101``, ``denoised``: the offsets and twist
        are linear in the errors, so both methods state the same interval) the scenario families'
        unflagged scans; verified only when `check` is given and did not flag the cloud, the
        cloud is within the studies' scope (`in_scope`, :func:`outside_study_scope`), and the
        demo study and every family verify the coverage (:func:`coverage_verified`).
    """
    study = COVERAGE_STUDY[name]
    if method == "denoised":
        kind = "denoised"
    elif method == "perturbed":
        kind = "jcgm101" if name in LINEAR_PARAMETERS else "reflected"
    else:
        msg = f"unknown method {method!r}"
        raise ValueError(msg)
    value = float(getattr(study, kind))
    verified = coverage_verified(round(value * DEMO_SCANS), DEMO_SCANS)
    if kind != "reflected":
        lowest, consistent = family_coverage(name)
        value = min(value, lowest) if math.isfinite(lowest) else value
        verified = verified and consistent
    return kind, value, verified and in_scope and check is not None and not check.flagged


def own_verdict(name: str, result: SectionUncertainty, study: ScenarioStudy) -> tuple[float, bool]:
    """Lowest coverage of `name` in this cloud's own study and whether it is verified for the cloud
    (every family's cell passes the rule and the cloud's residual check did not flag it)."""
    check = result.check
    return study.lowest(name), study.verified(name) and check is not None and not check.flagged
