"""Option groups several commands share (argparse), declared once."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from robocal_uncertainty.cli._common import DEFAULT_PAIRING_TOLERANCE_MS

if TYPE_CHECKING:
    from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
    from robocal_uncertainty.uncertainty.sources import OptionGroup


def add_force_arg(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--force", action="store_true", help=f"replace {what} if it exists (default: refuse)")


def add_base_unknown_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )


def add_campaign_args(p: argparse.ArgumentParser) -> None:
    """The campaign positional, --robot, --base-unknown and --pairing-tolerance-ms."""
    p.add_argument("campaign", help="campaign: .mcap file or rosbag2 directory")
    p.add_argument(
        "--robot", required=True, help="robot YAML file, shipped model name (paper_arm, ur10) or URDF file (.urdf)"
    )
    add_urdf_chain_args(p)
    add_base_unknown_arg(p)
    p.add_argument(
        "--pairing-tolerance-ms",
        type=float,
        default=DEFAULT_PAIRING_TOLERANCE_MS,
        help="recordings without our campaign metadata: pair each tracker point with the joint reading nearest in "
        "stamp when it is at most this far, ms (default %(default)g)",
    )
    add_accept_damaged_arg(p)


def add_accept_damaged_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--accept-damaged",
        action="store_true",
        help="a campaign file damaged in the middle (intact footer): use the poses before the damage and drop "
        "the rest (default: refuse)",
    )


def add_test_joint_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--test-joints", nargs="+", help="joint values of the test configurations, n_joints each")
    p.add_argument("--test-joints-file", help="CSV/whitespace file of test configurations, one per row")
    p.add_argument(
        "--degrees",
        action="store_true",
        help="test joint values are in degrees (default radians); a prismatic joint's are in m either way",
    )


def add_source_args(p: argparse.ArgumentParser, group: OptionGroup, *, unset_means: str | None = None) -> None:
    """The options of the registered uncertainty sources in `group` (generated from the registry:
    a source's options appear in every command that takes its group, with its help and unit).

    `unset_means`: every option is unset by default (None) and its help says what an unset
    option means instead of the registry's default (verify: "the calibration's").
    """
    from robocal_uncertainty.uncertainty.sources import source_options

    for option in source_options(group):
        kwargs: dict[str, Any] = option.argparse_kwargs()
        if unset_means is not None and not option.flag_only:
            kwargs["default"] = None
            text = option.help.replace("default %(default)s", f"default: {unset_means}")
            kwargs["help"] = text if text != option.help else f"{option.help} (default: {unset_means})"
        p.add_argument(option.flag, **kwargs)


def add_noise_args(p: argparse.ArgumentParser, *, unset_means: str | None = None) -> None:
    """The tracker and encoder noise models, shared by simulate, map, verify and the Monte Carlo
    commands (see :func:`add_source_args` for `unset_means`)."""
    add_source_args(p, "noise", unset_means=unset_means)


def encoder_noise(args: argparse.Namespace) -> Any:
    """The :class:`EncoderNoise` of --encoder-noise-deg and --linear-encoder-noise-um (SI)."""
    import numpy as np

    from robocal_uncertainty.core.instruments import EncoderNoise

    return EncoderNoise(
        half_width=float(np.radians(args.encoder_noise_deg)), linear_half_width=args.linear_encoder_noise_um * 1e-6
    )


def given_noise(
    args: argparse.Namespace, tracker: TrackerNoise, encoder: EncoderNoise
) -> tuple[TrackerNoise | None, EncoderNoise | None]:
    """The instruments of noise options parsed with ``unset_means``: each value given replaces
    the one of `tracker` / `encoder` (SI), the others are kept exactly; None for an instrument
    none of whose options was given."""
    from dataclasses import replace

    import numpy as np

    a, b = args.tracker_noise_um, args.tracker_noise_um_per_m
    revolute, linear = args.encoder_noise_deg, args.linear_encoder_noise_um
    tracker_fields = {k: v * 1e-6 for k, v in (("a", a), ("b", b)) if v is not None}
    encoder_fields: dict[str, float] = {}
    if revolute is not None:
        encoder_fields["half_width"] = float(np.radians(revolute))
    if linear is not None:
        encoder_fields["linear_half_width"] = linear * 1e-6
    return (
        replace(tracker, **tracker_fields) if tracker_fields else None,
        replace(encoder, **encoder_fields) if encoder_fields else None,
    )


def add_uncertainty_args(p: argparse.ArgumentParser, *, trials_default: str) -> None:
    p.add_argument(
        "--trials",
        default=trials_default,
        help="number of Monte Carlo trials, or 'auto' for the JCGM 101 adaptive procedure (default %(default)s)",
    )
    p.add_argument(
        "--max-trials", type=int, default=2_000_000, help="cap of the adaptive procedure (default %(default)s)"
    )
    p.add_argument("--coverage", type=float, default=0.95, help="coverage probability p (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the random streams (default %(default)s)")
    p.add_argument(
        "--lambda",
        dest="lambda_",
        default="auto",
        help="auto (L-curve corner), gcv, or a fixed value (default %(default)s)",
    )
    add_source_args(p, "selection")
    add_noise_args(p)
    add_model_error_arg(p)
    p.add_argument(
        "--workers", type=int, default=1, help="worker processes (never changes the result; default %(default)s)"
    )
    add_backend_arg(p)
    p.add_argument(
        "--budget",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run each source alone (uncertainty budget; default on)",
    )
    p.add_argument(
        "--budget-trials", type=int, default=2000, help="trials per source of the budget (default %(default)s)"
    )
    p.add_argument(
        "--sweeps",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="uncertainty against lambda and against the number of equations (report plots; default on)",
    )
    p.add_argument("--sweep-trials", type=int, default=300, help="trials per sweep point (default %(default)s)")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bars (default: shown when stderr is a terminal)"
    )
    p.add_argument(
        "--histograms",
        type=histogram_count,
        metavar="N|all",
        help="report: histogram figures for the first N test configurations, or all (default: all of up to 10, "
        "else the first 6 and the worst); not used by validate",
    )
    add_frame_and_convergence_args(p)


def histogram_count(text: str) -> int | str:
    if text == "all":
        return text
    try:
        count = int(text)
    except ValueError:
        count = -1
    if count < 0:
        msg = f"expected a count >= 0 or 'all', got {text!r}"
        raise argparse.ArgumentTypeError(msg)
    return count


class _FieldIsTheDefault(argparse.Action):
    """``--model-error-field``, the option that chose the field before it became the default:
    accepted so that scripts keep running, with a one-line note on stderr (the statement is the
    one the option asked for)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        kwargs.update(nargs=0, default=argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, *_: Any) -> None:
        print(
            f"{parser.prog}: note: --model-error-field is the default now and changes nothing (the model error is "
            "a field over the joint configurations; --independent-model-error draws it from pose to pose)",
            file=sys.stderr,
        )


def add_model_error_arg(p: argparse.ArgumentParser) -> None:
    """The model-error options (--independent-model-error: the residual source's model error independent
    from pose to pose instead of the default field; the former --model-error-field, a no-op with a note,
    cannot be combined with it)."""
    from robocal_uncertainty.uncertainty.sources import source_options

    group = p.add_mutually_exclusive_group()
    for option in source_options("model"):
        kwargs: dict[str, Any] = option.argparse_kwargs()
        group.add_argument(option.flag, **kwargs)
    group.add_argument("--model-error-field", action=_FieldIsTheDefault, help=argparse.SUPPRESS)


def add_frame_and_convergence_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        default="measurement",
        help="frame of the output positions: the frame of the campaign's points (default), or the robot base "
        "frame (for a tracker campaign the base transform's uncertainty then does not enter)",
    )
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="use an identification that did not converge instead of stopping with an error",
    )


def add_backend_arg(p: argparse.ArgumentParser) -> None:
    """--backend: which trial kernels walk the chain (the same draws; the result to rounding)."""
    from robocal_uncertainty.kernels import BACKEND_CHOICES

    p.add_argument(
        "--backend",
        choices=BACKEND_CHOICES,
        default="auto",
        help="trial kernels: numpy (reference), numba (compiled, extra 'fast'), cupy (GPU, extra 'gpu'), or auto, "
        "the fastest installed (default %(default)s; the same result to 1e-12 relative, recorded in the report)",
    )


def add_dask_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run the trial blocks on a Dask cluster: scheduler address, or 'local' for a LocalCluster of "
        "--workers processes (needs the [dask] extra; never changes the result)",
    )


def add_urdf_chain_args(p: argparse.ArgumentParser) -> None:
    """--base-link, --tip-link and --tool-point: the chain and the measured point of a ``--robot X.urdf``."""
    p.add_argument("--base-link", help="--robot X.urdf: the chain's base link (default: the URDF's root link)")
    p.add_argument(
        "--tip-link",
        help="--robot X.urdf: the chain's tip link, where the measured point is (default: the end of the first "
        "serial chain)",
    )
    p.add_argument(
        "--tool-point",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="--robot X.urdf: the measured point (probe centre, reflector) in the tip link, in METRES, when it is "
        "known ('0 0 0': the tip link is the probe, e.g. a fixed link added at it). Default: unknown, started "
        "from a least-squares fit to the campaign and not regularised",
    )
