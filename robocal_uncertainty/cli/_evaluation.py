"""The Monte Carlo commands' shared run and printing (evaluate, demo, replay): calibration
table, model adequacy, Table 2, budget, report."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.cli._common import Progress, count, in_cli_words, parse_lambda, parse_trials, seconds
from robocal_uncertainty.errors import ConfigError


def print_calibration(result: Any) -> None:
    print(
        f"Calibration of {result.model.name}: {count(result.n_poses, 'pose')}, "
        f"{int(result.estimated.sum())} parameters identified"
    )
    print(
        f"  lambda = {result.lambda_:.4g} ({result.lambda_method}), condition number "
        f"{result.condition_number:.3g}, {result.iterations} iterations, {result.message}"
    )
    print(
        f"  residual RMS {result.rms_before * 1e3:.4f} mm -> {result.rms_after * 1e3:.4f} mm, "
        f"max {result.max_before * 1e3:.4f} mm -> {result.max_after * 1e3:.4f} mm"
    )
    if getattr(result, "tool_initialised", "nominal") == "fit":
        print(
            "  tool point: not given (URDF: --tool-point), started from a least-squares fit to the campaign "
            "and not regularised"
        )
    if result.measurement.measures_orientation:
        _print_orientation_fit(result)
    from robocal_uncertainty.report.table2 import format_significant, round_to_uncertainty

    print("  parameter            nominal        estimate   1st-order std")
    kinds = result.model.layout.kinds
    held = result.held_by_regularisation
    for i, name in enumerate(result.parameter_names):
        if not result.estimated[i]:
            continue
        scale, unit, uscale, uunit = (
            (1e3, "mm", 1e6, "um")
            if kinds[i] == "length"
            else (float(np.degrees(1.0)), "deg", float(np.degrees(1.0)) * 1e3, "mdeg")
        )
        u = float(result.linearized_std[i])
        if held[i]:
            # The Tikhonov term, not the data, fixes it: its regularised std is no measurement.
            from robocal_uncertainty.report.document import held_note

            data_u = float(result.data_only_std[i])
            finite = bool(np.isfinite(data_u))
            why = held_note(data_u, kinds[i], micro="u")
            print(
                f"  {name:<16} {result.nominal[i] * scale:12.6g} {unit:<3} "
                f"{round_to_uncertainty(result.estimate[i] * scale, (data_u if finite else u) * scale):>12} "
                f"{unit:<3} {why}"
            )
            continue
        print(
            f"  {name:<16} {result.nominal[i] * scale:12.6g} {unit:<3} "
            f"{round_to_uncertainty(result.estimate[i] * scale, u * scale):>12} {unit:<3} "
            f"{format_significant(u * uscale):>8} {uunit}"
        )
    if result.dependencies:
        print(f"  not identifiable from the {result.measurement.quantity}s (kept at nominal):")
        from robocal_uncertainty.core.observability import describe_dependency

        for dep in result.dependencies:
            print(f"    {describe_dependency(dep)}")
    if held.any():
        from robocal_uncertainty.core.identification import HELD_STD_RATIO

        names = ", ".join(n for n, h in zip(result.parameter_names, held) if h)
        print(
            f"  held by regularisation ({names}): the data alone determine them more than "
            f"{HELD_STD_RATIO:g} times less well than the regularised fit says (data-only u: lambda = 0); "
            "their values come from the Tikhonov term, not from a measurement"
        )
    for warning in result.warnings:
        print(f"  warning: {warning}")


def _print_orientation_fit(result: Any) -> None:
    """The rotation residuals and the weighting of a calibration from 6-DOF measurements."""
    stated, used = result.measurement.std, 1.0 / result.measurement.weights
    print(
        f"  rotation residual RMS {result.rotation_rms_before * 1e3:.5g} mrad -> "
        f"{result.rotation_rms_after * 1e3:.5g} mrad (position RMS above: the position part)"
    )

    def triple(std: Any) -> str:
        return (
            f"position ({', '.join(f'{v * 1e6:.3g}' for v in std[:3])}) um, "
            f"rotation ({', '.join(f'{v * 1e6:.3g}' for v in std[3:])}) urad"
        )

    if result.weighting == "variance_components":
        print(
            f"  weighting: each residual divided by its scatter (variance components, "
            f"{result.weighting_iterations} fits): {triple(used)}; stated: {triple(stated)}"
        )
    else:
        print(f"  weighting: each residual divided by its stated standard uncertainty, {triple(stated)}")


def print_adequacy(result: Any) -> None:
    from robocal_uncertainty.uncertainty.sources.registry import source_with_role

    ad = result.model_adequacy
    if ad.adequate:
        print(
            f"Model adequacy: residuals consistent with the stated tracker and encoder noise "
            f"(p = {ad.p_value:.3g}); no model error left for the residual source"
        )
    else:
        std = ad.standard_uncertainty
        u = f"({', '.join(f'{v * 1e6:.1f}' for v in std[:3])}) um"
        if len(std) > 3:  # 6-DOF residuals: the rotation part is in rad
            u = f"position {u}, rotation ({', '.join(f'{v * 1e6:.1f}' for v in std[3:])}) urad"
        residual = source_with_role("model_error")
        used = "included" if residual in result.settings.sources else f"NOT included: add --sources ...,{residual}"
        print(
            f"Model adequacy: residuals exceed the stated noise (p = {ad.p_value:.3g}); model error "
            f"u = {u} per measurement-frame axis, {used}"
        )
        me_field = getattr(result, "model_error_field", None)
        if me_field is not None:
            print(f"  {me_field.describe()}")
    repeated = getattr(ad, "repeated_poses", 0)
    if repeated:
        print(
            f"note: {count(repeated, 'pose')} repeat an earlier pose's joint readings: each distinct configuration "
            "counts once in the residual degrees of freedom"
        )
    if not ad.trustworthy:
        print(f"warning: {ad.trust_note}")


def uncertainty_settings(args: argparse.Namespace, campaign: Any, sources: Sequence[str]) -> Any:
    """The :class:`UncertaintySettings` of the parsed noise and source arguments (the node's
    parameters go through the same :func:`build_uncertainty_settings`)."""
    from robocal_uncertainty.uncertainty.calibration.settings import build_source_settings
    from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY

    between = None
    if getattr(args, "between_session", None):
        from robocal_uncertainty.uncertainty.sessions.between import between_sessions_from_file

        between = between_sessions_from_file(args.between_session)
    # Every registered source's options, as parsed (each source turns its own into settings).
    values = {
        option.dest: getattr(args, option.dest, False if option.flag_only else option.default)
        for spec in SOURCE_REGISTRY.values()
        for option in spec.options
    }
    return build_source_settings(sources=tuple(sources), values=values, between_session=between)


def evaluation_options(
    args: argparse.Namespace, sources: Sequence[str], test_joints: NDArray[np.float64] | None
) -> Any:
    """The :class:`EvaluationSettings` of the parsed uncertainty arguments (the node's
    parameters go through the same :func:`build_evaluation_settings`)."""
    from robocal_uncertainty.kernels import get_backend
    from robocal_uncertainty.uncertainty import parse_sources
    from robocal_uncertainty.uncertainty.calibration.settings import build_evaluation_settings

    get_backend(args.backend)  # an unknown or missing backend stops here, before any work
    for option in ("budget_trials", "sweep_trials", "max_trials"):
        value = getattr(args, option)
        if value <= 0:
            msg = f"--{option.replace('_', '-')} must be a positive integer, got {value}"
            raise ConfigError(msg)
    return build_evaluation_settings(
        uncertainty_settings(args, None, parse_sources(list(sources))),
        lambda_=parse_lambda(args.lambda_),
        test_joints=test_joints,
        trials=parse_trials(args.trials),
        seed=args.seed,
        coverage=args.coverage,
        max_trials=args.max_trials,
        frame=args.frame,
        accept_unconverged=args.accept_unconverged,
        budget=args.budget,
        budget_trials=args.budget_trials,
        sweeps=args.sweeps,
        sweep_trials=args.sweep_trials,
        backend=args.backend,
    )


def evaluate_and_report(
    model: Any,
    campaign: Any,
    test_joints: NDArray[np.float64],
    *,
    sources: Sequence[str],
    args: argparse.Namespace,
    out_dir: Path,
    label: str,
) -> Any:
    """Evaluate through :func:`robocal_uncertainty.app.evaluate`, print and write the report:
    shared by ``evaluate`` and ``demo``. Returns the uncertainty result."""
    from robocal_uncertainty.app import evaluate
    from robocal_uncertainty.montecarlo.executor import RunContext, open_executor

    options = evaluation_options(args, sources, test_joints)
    bars = Progress(not args.no_progress, label, max_trials=args.max_trials)
    try:
        # --dask (evaluate only) or --workers: one executor for the main run, budget and sweeps.
        with open_executor(workers=args.workers, dask=getattr(args, "dask", None)) as executor:
            run = RunContext(executor=executor, progress=bars.main)
            evaluation = evaluate(
                model,
                campaign,
                options,
                run=run,
                phase_progress=bars.phase,
                field_correction=getattr(args, "field_correction", False),
            )
    finally:
        bars.close()
    print_evaluation(evaluation, options, model, out_dir, bars, args)
    return evaluation.uncertainty


def refuse_unconverged_statement(result: Any) -> None:
    """Stop with one line when the Monte Carlo ran but is no statement (its spread disagrees with
    its own first-order GUM statement): its numbers are never printed or written."""
    problems = getattr(result, "not_converged", ())
    if not problems:
        return
    from robocal_uncertainty.errors import ConvergenceError
    from robocal_uncertainty.uncertainty.statement_check import GUM_DISAGREEMENT_FACTOR

    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    msg = (
        f"the Monte Carlo did not converge to a statement: {problems[0]}{more}; its trials do not re-identify the "
        f"calibration's solution (honest runs stay within a factor {GUM_DISAGREEMENT_FACTOR:g}; causes: a unit "
        "slip, a wrong robot model, or too few poses for the model error); no statement printed, no report written"
    )
    raise ConvergenceError(msg)


def print_evaluation(
    evaluation: Any, options: Any, model: Any, out_dir: Path, bars: Progress, args: argparse.Namespace
) -> None:
    """Print an :class:`~robocal_uncertainty.app.Evaluation` and write its report (an
    earlier report's files in `out_dir` are removed first; ``--force`` was checked)."""
    from robocal_uncertainty.app.output_paths import clear_earlier_report
    from robocal_uncertainty.report import format_budget, format_table2, write_report

    result = evaluation.uncertainty
    elapsed = bars.elapsed()
    print_calibration(evaluation.calibration)
    print()
    print_adequacy(result)
    refuse_unconverged_statement(result)
    print(f"Positions in frame {result.frame_id} ({result.frame} frame; --frame base|measurement)")
    print(format_table2(result))
    adaptive = result.adaptive
    if adaptive is not None:
        state = "converged" if adaptive.converged else "NOT converged"
        print(
            f"adaptive JCGM 101 7.9: {state} at {adaptive.n_dig} significant digits of u, "
            f"{adaptive.n_sequences} sequences of {adaptive.sequence_trials} trials"
        )
    backend = "" if result.backend is None else f", backend {result.backend.describe()}"
    print(f"{result.n_trials} trials in {seconds(elapsed)} ({result.n_trials / elapsed:.0f} trials/s{backend})")
    if evaluation.budget:
        print()
        print(format_budget(evaluation.budget))
        print(f"(each source alone, {options.budget_trials} trials each)")
    for note in evaluation.notes:
        print(f"note: {in_cli_words(note)}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    clear_earlier_report(out_dir)
    bars.note(f"writing the report to {out_dir} ...")
    path = write_report(
        out_dir,
        result,
        robot_name=model.name,
        budget=dict(evaluation.budget) or None,
        sweeps=list(evaluation.sweeps) if options.sweeps else None,
        input_warnings=evaluation.input_warnings,
        histograms=getattr(args, "histograms", None),
    )
    print(f"report written to {path}")
