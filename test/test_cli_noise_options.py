"""The instrument noise options of every command come from the source registry, with the
flags, defaults and meanings they had when map and verify declared their own."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from robocal_uncertainty.cli import _build_parser
from robocal_uncertainty.cli._options import given_noise
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY, source_options, source_parameters

NOISE = {
    "--tracker-noise-um": 5.0,
    "--tracker-noise-um-per-m": 0.0,
    "--encoder-noise-deg": 0.005,
    "--linear-encoder-noise-um": 5.0,
}
"""The flags and defaults map, simulate, calibrate and evaluate have always had."""


def _command(name: str) -> argparse.ArgumentParser:
    parser = _build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices[name]  # type: ignore[index,no-any-return]


def _options(name: str) -> dict[str, argparse.Action]:
    return {flag: action for action in _command(name)._actions for flag in action.option_strings}


def test_the_registry_holds_the_noise_flags_and_defaults() -> None:
    assert {option.flag: option.default for option in source_options("noise")} == NOISE


@pytest.mark.parametrize("command", ["map", "evaluate", "validate", "simulate", "calibrate", "compensate"])
def test_commands_take_the_noise_options_with_their_defaults(command: str) -> None:
    options = _options(command)
    for flag, default in NOISE.items():
        assert options[flag].default == default, (command, flag)
        assert options[flag].type is float


def test_verify_noise_options_are_unset_and_say_they_default_to_the_calibrations() -> None:
    options = _options("verify")
    for flag in NOISE:
        assert options[flag].default is None, flag
        assert "default: the calibration's" in str(options[flag].help), flag
        assert "%(default)s" not in str(options[flag].help)


def _verify_args(*argv: str) -> argparse.Namespace:
    return _build_parser().parse_args(["verify", "cal.json", "check.mcap", "--robot", "paper_arm", *argv])


def test_verify_keeps_every_value_not_given_from_the_calibration() -> None:
    tracker = TrackerNoise(a=3.3e-6, b=1.7e-6)
    encoder = EncoderNoise(half_width=1.234e-4, linear_half_width=4.4e-6)
    assert given_noise(_verify_args(), tracker, encoder) == (None, None)
    new_tracker, new_encoder = given_noise(_verify_args("--tracker-noise-um", "7"), tracker, encoder)
    assert new_encoder is None
    assert new_tracker == TrackerNoise(a=7 * 1e-6, b=1.7e-6)  # the conversion of every command
    new_tracker, new_encoder = given_noise(_verify_args("--tracker-noise-um-per-m", "2"), tracker, encoder)
    assert new_tracker == TrackerNoise(a=3.3e-6, b=2 * 1e-6)
    _, new_encoder = given_noise(_verify_args("--encoder-noise-deg", "0.01"), tracker, encoder)
    assert new_encoder == EncoderNoise(half_width=float(np.radians(0.01)), linear_half_width=4.4e-6)
    # New in verify with the registry's options: the prismatic joints' reading error.
    _, new_encoder = given_noise(_verify_args("--linear-encoder-noise-um", "2.5"), tracker, encoder)
    assert new_encoder == EncoderNoise(half_width=1.234e-4, linear_half_width=2.5 * 1e-6)


def test_between_session_is_the_registry_option_of_the_command_line_only() -> None:
    (option,) = source_options("session")
    assert option.flag == "--between-session" and option in SOURCE_REGISTRY["between_session"].options
    args = _build_parser().parse_args(["evaluate", "c.mcap", "--robot", "paper_arm", "--between-session", "cal.json"])
    assert args.between_session == "cal.json"
    unset = _build_parser().parse_args(["evaluate", "c.mcap", "--robot", "paper_arm"])
    assert unset.between_session is None
    assert _options("evaluate")["--between-session"].metavar == ("CAL.json",)
    # The node has no parameter for it: the option stays unset there.
    assert option.from_parameters({p.name: p.default for p in source_parameters()}) is None
    assert "--between-session" not in _options("validate")
