"""The registry of uncertainty sources: an explicit list of the shipped ones, by name.

Every command, node parameter and report lists the sources from here; a source added to
:data:`BUILTIN_SOURCES` (or registered at run time with :func:`register_source`) appears
in all of them.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sources.base import (
    NodeParameter,
    OptionGroup,
    Source,
    SourceOption,
    SourceRole,
    SourceSpec,
    TrialContext,
)
from robocal_uncertainty.uncertainty.sources.between_session import BETWEEN_SESSION
from robocal_uncertainty.uncertainty.sources.instrument import ENCODER, TRACKER, TRACKER_ORIENTATION
from robocal_uncertainty.uncertainty.sources.model_error import RESIDUAL
from robocal_uncertainty.uncertainty.sources.selection import LAMBDA, N_POSES, POSE_CHOICE

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = [
    "BUILTIN_SOURCES",
    "SOURCES",
    "SOURCE_DESCRIPTIONS",
    "SOURCE_REGISTRY",
    "build_sources",
    "default_sources",
    "parse_sources",
    "register_source",
    "source_options",
    "source_parameters",
    "source_settings_fields",
    "source_with_role",
    "sources_given_options",
    "sources_help",
    "sources_in_sweeps",
    "sources_with_role",
]


BUILTIN_SOURCES: tuple[SourceSpec, ...] = (
    TRACKER,
    ENCODER,
    LAMBDA,
    N_POSES,
    POSE_CHOICE,
    RESIDUAL,
    TRACKER_ORIENTATION,
    BETWEEN_SESSION,
)
"""Every source the package ships, in registry order (the order of a result's columns and budget)."""

SOURCE_REGISTRY: dict[str, SourceSpec] = {}


def register_source(spec: SourceSpec) -> None:
    """Add a source kind; its name must be new and its stream id unique.

    Raises
    ------
    ConfigError
        Name already registered, or its stream id collides with another's.
    """
    if spec.name in SOURCE_REGISTRY or spec.name == "all" or not spec.name.isidentifier():
        msg = f"source name {spec.name!r} is taken or not an identifier"
        raise ConfigError(msg)
    if any(other.stream_id == spec.stream_id for other in SOURCE_REGISTRY.values()):
        msg = f"source name {spec.name!r} collides with another source's random stream id; choose another name"
        raise ConfigError(msg)
    SOURCE_REGISTRY[spec.name] = spec


class _Descriptions(Mapping[str, str]):
    """Live view name -> description of the registry (sources registered later included)."""

    def __getitem__(self, key: str) -> str:
        return SOURCE_REGISTRY[key].description

    def __iter__(self) -> Iterator[str]:
        return iter(SOURCE_REGISTRY)

    def __len__(self) -> int:
        return len(SOURCE_REGISTRY)


SOURCE_DESCRIPTIONS: Mapping[str, str] = _Descriptions()
for _spec in BUILTIN_SOURCES:
    register_source(_spec)

SOURCES: tuple[str, ...] = tuple(spec.name for spec in BUILTIN_SOURCES if spec is not BETWEEN_SESSION)
"""The built-in sources of a single session, in registry order (``between_session`` needs a
calibration of several sessions and is listed apart)."""


def sources_help() -> str:
    """``"tracker, encoder, ... or all"`` from the registry, for help texts and node parameters."""
    return f"{', '.join(SOURCE_REGISTRY)}, or all"


def build_sources(settings: UncertaintySettings, context: TrialContext) -> tuple[Source, ...]:
    """The enabled sources of `settings` for one evaluation, in registry order."""
    return tuple(SOURCE_REGISTRY[name].build(settings, context) for name in SOURCE_REGISTRY if name in settings.sources)


def parse_sources(text: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Parse ``"tracker,encoder"`` or ``"all"`` into a tuple of registered source names.

    Raises
    ------
    ConfigError
        Unknown or empty source names.
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    names = [s.strip() for s in items if s.strip()]
    known = tuple(SOURCE_REGISTRY)
    if names == ["all"]:
        return known
    unknown = [s for s in names if s not in SOURCE_REGISTRY]
    if unknown:
        msg = f"unknown uncertainty source(s) {unknown}; known: {', '.join(known)} or 'all'"
        raise ConfigError(msg)
    if not names:
        msg = f"no uncertainty source given; known: {', '.join(known)}"
        raise ConfigError(msg)
    return tuple(dict.fromkeys(names))


def default_sources(measures_orientation: bool = False) -> tuple[str, ...]:
    """The default sources of every command, node and API call: the validated statement.

    ``tracker``, ``encoder`` and ``residual`` (the model error the adequacy test finds; it
    adds nothing when the residuals are consistent with the stated noise), plus
    ``tracker_orientation`` when the campaign measures orientations (a 6-DOF tracker).
    This is the set ``validate`` checks against held-out poses; leaving ``residual`` out
    states only the instrument noise, 5-8 times below the validated u on the UR10 series.

    Parameters
    ----------
    measures_orientation : bool
        The campaign's measurement type holds an orientation.

    Returns
    -------
    tuple of str, in registry order.
    """
    names = ("tracker", "encoder", "residual") + (("tracker_orientation",) if measures_orientation else ())
    return tuple(name for name in SOURCE_REGISTRY if name in names)


def sources_with_role(sources: tuple[str, ...], *roles: SourceRole) -> tuple[str, ...]:
    """The sources of `sources` whose :attr:`SourceSpec.role` is one of `roles`, in their order."""
    return tuple(name for name in sources if SOURCE_REGISTRY[name].role in roles)


def source_with_role(role: SourceRole) -> str:
    """The registered source of `role` (the first in registry order).

    Raises
    ------
    ConfigError
        No source has that role.
    """
    for spec in SOURCE_REGISTRY.values():
        if spec.role == role:
            return spec.name
    msg = f"no uncertainty source has the role {role!r}"
    raise ConfigError(msg)


def sources_in_sweeps(sources: tuple[str, ...]) -> tuple[str, ...]:
    """The sources of `sources` drawn at every sweep point (:attr:`SourceSpec.in_sweeps`), in their order."""
    return tuple(name for name in sources if SOURCE_REGISTRY[name].in_sweeps)


def source_options(group: OptionGroup) -> tuple[SourceOption, ...]:
    """The command-line options of the registered sources in `group`, in registry order."""
    return tuple(option for spec in SOURCE_REGISTRY.values() for option in spec.options if option.group == group)


def sources_given_options(group: OptionGroup, values: Mapping[str, Any]) -> tuple[str, ...]:
    """The registered sources with an option of `group` given in `values` (keyed by the option's
    ``dest``; None means not given), in registry order: giving a source's own input (a
    between-session file) asks for that source."""
    return tuple(
        name
        for name, spec in SOURCE_REGISTRY.items()
        if any(option.group == group and values.get(option.dest) is not None for option in spec.options)
    )


def source_parameters() -> tuple[NodeParameter, ...]:
    """The uncertainty node's parameters of every registered source's settings, in registry order."""
    return tuple(
        parameter for spec in SOURCE_REGISTRY.values() for option in spec.options for parameter in option.parameters
    )


def source_settings_fields(values: Mapping[str, Any]) -> dict[str, object]:
    """The :class:`UncertaintySettings` fields of every registered source's option `values`.

    Parameters
    ----------
    values : mapping
        Option values by :attr:`SourceOption.dest`, in the options' units (as the command
        line parses them, or :meth:`SourceOption.from_parameters` of the node's parameters).

    Raises
    ------
    KeyError
        A registered source's option has no value in `values`.
    """
    fields: dict[str, object] = {}
    for spec in SOURCE_REGISTRY.values():
        if spec.to_settings is not None:
            fields.update(spec.to_settings(values))
    return fields
