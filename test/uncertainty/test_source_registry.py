"""The source registry: an explicit list without an import cycle, roles instead of names,
and the command-line options and node parameters generated from the sources' own specs."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.cli._options import add_noise_args, add_uncertainty_args
from robocal_uncertainty.montecarlo.distributions import IndependentRectangular
from robocal_uncertainty.uncertainty.sources import (
    BUILTIN_SOURCES,
    SOURCE_REGISTRY,
    AdditiveSource,
    NodeParameter,
    SourceOption,
    SourceSpec,
    TrialContext,
    UncertaintySettings,
    register_source,
    source_options,
    source_parameters,
    source_with_role,
    sources_in_sweeps,
    sources_with_role,
)

REPO = Path(__file__).resolve().parents[2]


def test_the_registry_is_the_explicit_list_in_its_order() -> None:
    assert tuple(SOURCE_REGISTRY) == tuple(spec.name for spec in BUILTIN_SOURCES)
    assert tuple(SOURCE_REGISTRY) == (
        "tracker",
        "encoder",
        "lambda",
        "n_poses",
        "pose_choice",
        "residual",
        "tracker_orientation",
        "between_session",
    )


def test_importing_the_sources_does_not_import_the_between_session_estimation() -> None:
    # The cycle sources -> between_sessions -> sources is gone: the registry holds the
    # between-session source without the module that estimates the component.
    code = (
        "import sys; import robocal_uncertainty.uncertainty.sources as s; "
        "assert 'between_session' in s.SOURCE_REGISTRY; "
        "print('robocal_uncertainty.uncertainty.sessions.between' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(REPO)},
    )
    assert out.stdout.strip() == "False"


def test_roles_replace_the_names_the_preparation_and_the_sweeps_tested() -> None:
    every = tuple(SOURCE_REGISTRY)
    assert sources_with_role(every, "lambda") == ("lambda",)
    assert sources_with_role(every, "pose_count", "pose_subset") == ("n_poses", "pose_choice")
    assert sources_with_role(every, "model_error") == ("residual",)
    assert source_with_role("pose_subset") == "pose_choice"
    assert sources_in_sweeps(every) == ("tracker", "encoder", "residual")
    assert sources_in_sweeps(("lambda", "between_session")) == ()


def _parser(add) -> argparse.ArgumentParser:  # type: ignore[no-untyped-def]
    p = argparse.ArgumentParser()
    add(p)
    return p


def test_generated_options_parse_as_the_hand_written_ones_did() -> None:
    p = _parser(lambda q: add_uncertainty_args(q, trials_default="auto"))
    args = p.parse_args([])
    assert (args.tracker_noise_um, args.tracker_noise_um_per_m) == (5.0, 0.0)
    assert (args.encoder_noise_deg, args.linear_encoder_noise_um) == (0.005, 5.0)
    assert (args.lambda_range, args.min_poses, args.subset_size, args.independent_model_error) == (
        None,
        None,
        None,
        False,
    )
    args = p.parse_args(
        ["--lambda-range", "1e-3", "2", "--min-poses", "20", "--subset-size", "30", "--independent-model-error"]
    )
    assert args.lambda_range == [1e-3, 2.0]
    assert (args.min_poses, args.subset_size, args.independent_model_error) == (20, 30, True)
    with pytest.raises(SystemExit):
        p.parse_args(["--min-poses", "2.5"])


def test_node_parameters_carry_units_and_ranges_from_the_sources() -> None:
    by_name = {p.name: p for p in source_parameters()}
    assert list(by_name) == [
        "tracker_noise_um",
        "tracker_noise_um_per_m",
        "encoder_noise_deg",
        "linear_encoder_noise_um",
        "lambda_range_low",
        "lambda_range_high",
        "min_poses",
        "subset_size",
        "independent_model_error",
    ]
    assert (by_name["encoder_noise_deg"].unit, by_name["encoder_noise_deg"].high) == ("deg", 10.0)
    assert (by_name["min_poses"].default, by_name["min_poses"].low) == (0, 0)
    assert by_name["independent_model_error"].default is False


def _drift(settings: UncertaintySettings, ctx: TrialContext) -> AdditiveSource:
    return AdditiveSource(
        "test_drift", IndependentRectangular(np.zeros(ctx.n_test * 3)), (("predictions", (ctx.n_test, 3)),)
    )


def test_a_registered_source_brings_its_option_and_parameter_everywhere() -> None:
    option = SourceOption(
        "--test-drift-um",
        "test drift half-width, um (default %(default)s)",
        "noise",
        "um",
        float,
        1.5,
        parameters=(NodeParameter("test_drift_um", 1.5, "Test drift half-width", "um", 0.0, 10.0),),
    )
    register_source(SourceSpec("test_drift", "test source", True, _drift, options=(option,)))
    try:
        assert option in source_options("noise")
        assert source_parameters()[-1].name == "test_drift_um"
        p = _parser(add_noise_args)
        assert p.parse_args([]).test_drift_um == 1.5
        assert p.parse_args(["--test-drift-um", "3"]).test_drift_um == 3.0
        assert "test drift half-width, um (default 1.5)" in " ".join(p.format_help().split())
    finally:
        del SOURCE_REGISTRY["test_drift"]
    assert "--test-drift-um" not in _parser(add_noise_args).format_help()


def _all_options() -> tuple[SourceOption, ...]:
    return tuple(option for spec in SOURCE_REGISTRY.values() for option in spec.options)


def test_node_parameters_give_the_settings_the_command_line_gives() -> None:
    from robocal_uncertainty.uncertainty.calibration.settings import build_source_settings, build_uncertainty_settings

    # Defaults: the node's zeros stand for the options left unset.
    node = {p.name: p.default for p in source_parameters()}
    from_node = {o.dest: o.from_parameters(node) for o in _all_options()}
    cli = vars(_parser(lambda q: add_uncertainty_args(q, trials_default="auto")).parse_args([]))
    from_cli = {o.dest: cli.get(o.dest) for o in _all_options()}  # --between-session: evaluate only
    assert from_node == from_cli
    assert build_source_settings(sources="all", values=from_node) == build_source_settings(
        sources="all", values=from_cli
    )
    # Set values (the node's integer YAML values included), against the keyword builder.
    node.update(
        tracker_noise_um=7,
        tracker_noise_um_per_m=1.5,
        encoder_noise_deg=0.01,
        linear_encoder_noise_um=3,
        lambda_range_low=0.001,
        lambda_range_high=2.0,
        min_poses=20,
        subset_size=30,
        independent_model_error=True,
    )
    built = build_source_settings(sources="all", values={o.dest: o.from_parameters(node) for o in _all_options()})
    expected = build_uncertainty_settings(
        sources="all",
        tracker_noise_um=7.0,
        tracker_noise_um_per_m=1.5,
        encoder_noise_deg=0.01,
        linear_encoder_noise_um=3.0,
        independent_model_error=True,
        lambda_range=(0.001, 2.0),
        min_poses=20,
        subset_size=30,
    )
    assert built == expected
    assert built.tracker_noise.a == 7e-6 and built.encoder_noise.half_width == np.radians(0.01)
    assert (built.lambda_range, built.min_poses, built.subset_size, built.model_error) == (
        (0.001, 2.0),
        20,
        30,
        "independent",
    )


def test_a_given_source_option_asks_for_its_source() -> None:
    # `evaluate --between-session CAL.json` adds the source whose option it is, found by the
    # registry (the command names no source).
    from robocal_uncertainty.uncertainty.sources.registry import sources_given_options

    assert sources_given_options("session", {"between_session": "cal.json"}) == ("between_session",)
    assert sources_given_options("session", {"between_session": None}) == ()
    assert sources_given_options("session", {}) == ()
    # An option of another group given does not count for this one.
    assert sources_given_options("noise", {"between_session": "cal.json"}) == ()
