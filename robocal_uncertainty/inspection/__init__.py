"""Blade-section inspection: point clouds, section algorithms and their CMM Monte Carlo.

``read_point_cloud`` / ``read_nominal_section`` (and the shipped blade readers) give SI data;
``evaluate_section`` computes the reference paper's nine section parameters; ``section_uncertainty`` runs
the batched Monte Carlo under the CMM model (``load_instrument``) with the GUM comparison
(method ``denoised``: the error sampled around ``denoise_section``'s cloud, whose residual check
flags a cloud the denoising did not follow); ``coverage_study`` measures the intervals' coverage
over scenario families of simulated parts (the stored Rotor 37 study, or a user's own part,
layout and instrument) and ``coverage_rule`` says whether a study verifies it.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.core.instruments.cmm import (
        SOURCE_NAMES,
        CmmInstrument,
        ErrorSource,
        load_instrument,
        point_displacements,
        point_error_sources,
        reference_paper_instrument,
    )
    from robocal_uncertainty.inspection.bias_correction import MAX_MIN_PARAMETERS, BiasCorrection, bias_corrections
    from robocal_uncertainty.inspection.denoise import DenoisedCloud, ResidualCheck, denoise_section
    from robocal_uncertainty.inspection.nominal_curve import ClosestPoints, NominalCurve
    from robocal_uncertainty.inspection.point_cloud import (
        LENGTH_UNITS,
        NominalSection,
        PointCloud,
        read_cascade_profile,
        read_nominal_section,
        read_point_cloud,
        read_rotor37_section,
    )
    from robocal_uncertainty.inspection.registration import Registration, register_to_nominal
    from robocal_uncertainty.inspection.resolution import ResolutionEnvelope, resolution_envelope
    from robocal_uncertainty.inspection.section import (
        PARAMETER_NAMES,
        PARAMETER_UNITS,
        SectionEvaluation,
        SectionOptions,
        SectionParameters,
        chord_length,
        evaluate_section,
        max_thickness,
        profile_deviations,
    )
    from robocal_uncertainty.inspection.section_mc import (
        SectionUncertainty,
        full_section_trials,
        prepare_trials,
        section_uncertainty,
    )
    from robocal_uncertainty.inspection.segmentation import REGIONS, Segmentation, segment_section
    from robocal_uncertainty.inspection.simulate import simulate_section_scan

__all__ = [
    "LENGTH_UNITS",
    "MAX_MIN_PARAMETERS",
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "REGIONS",
    "SOURCE_NAMES",
    "BiasCorrection",
    "ClosestPoints",
    "CmmInstrument",
    "DenoisedCloud",
    "ErrorSource",
    "NominalCurve",
    "NominalSection",
    "PointCloud",
    "Registration",
    "ResidualCheck",
    "ResolutionEnvelope",
    "SectionEvaluation",
    "SectionOptions",
    "SectionParameters",
    "SectionUncertainty",
    "Segmentation",
    "bias_corrections",
    "chord_length",
    "denoise_section",
    "evaluate_section",
    "full_section_trials",
    "load_instrument",
    "max_thickness",
    "point_displacements",
    "point_error_sources",
    "prepare_trials",
    "profile_deviations",
    "read_cascade_profile",
    "read_nominal_section",
    "read_point_cloud",
    "read_rotor37_section",
    "reference_paper_instrument",
    "register_to_nominal",
    "resolution_envelope",
    "section_uncertainty",
    "segment_section",
    "simulate_section_scan",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
