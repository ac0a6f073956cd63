"""The uncertainty sources of a calibration Monte Carlo, as objects in a registry.

A source is one input of JCGM 101's model: it draws its values for a block of trials
from its own random stream and applies them to a batch of trials (perturbed points,
joint readings, regularisation parameter, pose selection, prediction offsets). Smooth
sources carry their noise model as a :mod:`robocal_uncertainty.montecarlo` distribution,
so the Monte Carlo samples and the GUM variance come from one definition, and they act
additively on named fields of the batch, so the GUM sensitivities follow from the
calibration's linearisation. Each source draws from ``SeedSequence(seed, spawn_key=(block,
stream_id))`` with a stream id fixed by its name: adding or removing a source never
changes another source's draws.

The package: :mod:`.base` (protocol, context, batch, spec), one module per family of
sources (:mod:`.instrument`, :mod:`.selection`, :mod:`.model_error`,
:mod:`.between_session`), :mod:`.registry` (the explicit list, parsing, building) and
:mod:`.settings` (:class:`UncertaintySettings`). How to add a source: ``docs/extending.md``.
"""

from __future__ import annotations

from robocal_uncertainty.uncertainty.sources.base import (
    ADDITIVE_FIELDS,
    AdditiveSource,
    NodeParameter,
    OptionGroup,
    Source,
    SourceOption,
    SourceRole,
    SourceSpec,
    TrialBatch,
    TrialContext,
    stream_id,
)
from robocal_uncertainty.uncertainty.sources.registry import (
    BUILTIN_SOURCES,
    SOURCE_DESCRIPTIONS,
    SOURCE_REGISTRY,
    SOURCES,
    build_sources,
    default_sources,
    parse_sources,
    register_source,
    source_options,
    source_parameters,
    source_settings_fields,
    source_with_role,
    sources_help,
    sources_in_sweeps,
    sources_with_role,
)
from robocal_uncertainty.uncertainty.sources.selection import LambdaSource, PoseChoiceSource, PoseCountSource
from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = [
    "ADDITIVE_FIELDS",
    "BUILTIN_SOURCES",
    "SOURCES",
    "SOURCE_DESCRIPTIONS",
    "SOURCE_REGISTRY",
    "AdditiveSource",
    "LambdaSource",
    "NodeParameter",
    "OptionGroup",
    "PoseChoiceSource",
    "PoseCountSource",
    "Source",
    "SourceOption",
    "SourceRole",
    "SourceSpec",
    "TrialBatch",
    "TrialContext",
    "UncertaintySettings",
    "build_sources",
    "default_sources",
    "parse_sources",
    "register_source",
    "source_options",
    "source_parameters",
    "source_settings_fields",
    "source_with_role",
    "sources_help",
    "sources_in_sweeps",
    "sources_with_role",
    "stream_id",
]
