"""Section inspection service: a blade section's parameters and their uncertainty.

:func:`inspect_section` reads a measured section (a CMM text export, or the ``PointCloud2``
messages of a bag), a nominal section (a file, or a shipped blade), an instrument YAML, and
runs the batched Monte Carlo of the nine section parameters with the GUM comparison and the
bias-corrected intervals of the max/min-defined parameters. The default method ``denoised``
samples the error around a denoised cloud (locally adaptive windows); every cloud gets the
denoising's residual check (``result.check``), which flags a cloud whose form the denoising did
not follow (its intervals are then not verified for it). Measured coverage: the stored studies
(:mod:`~robocal_uncertainty.inspection.stored_studies`)
``COVERAGE_STUDY`` (demo scenario) and ``FAMILY_STUDY`` (scenario families with local features);
``perturbed`` perturbs the measured cloud as the reference paper does.
:func:`section_demo` does the same on a simulated 1 836-point CMM scan of the shipped NASA
Rotor 37 section at the reference paper's size, with a known truth. With ``repeat_scans``,
:func:`inspect_section` also evaluates k >= 2 repeated scans of the same section with the same
algorithm and adds their standard deviation to the GUM budget (the reference paper's u3, repeatability).

Shipped nominals (``--nominal``): ``rotor37`` (surface 2 scaled by 7.14: maximum thickness
30.37 mm, the reference paper's blade 30.365 mm), ``rotor37:K`` (surface K, same scale), ``cascade``
(DFVLR L030-4 at a 100 mm chord). Shipped instruments: ``cmm_reference_paper`` (the default).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.bagio.point_cloud2 import read_point_cloud2
from robocal_uncertainty.core.instruments.cmm import CmmInstrument, load_instrument
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.inspection.bias_correction import BiasCorrection, bias_corrections
from robocal_uncertainty.inspection.coverage_study import ScenarioStudy, run_scenario_study, scenario_from_cloud
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import (
    NominalSection,
    PointCloud,
    read_cascade_profile,
    read_nominal_section,
    read_point_cloud,
    read_rotor37_section,
)
from robocal_uncertainty.inspection.section import evaluate_section
from robocal_uncertainty.inspection.section_mc import SectionUncertainty, canonical_method, section_uncertainty
from robocal_uncertainty.inspection.simulate import simulate_section_scan
from robocal_uncertainty.montecarlo.engine import AdaptiveSettings, ProgressCallback

__all__ = [
    "DEMO_SCENARIO",
    "REPEAT_TOLERANCE",
    "ROTOR37_SCALE",
    "SectionInspection",
    "inspect_section",
    "load_section_cloud",
    "load_section_nominal",
    "resolve_instrument",
    "section_coverage_study",
    "section_demo",
]

ROTOR37_SCALE = 7.14
"""Scale of the shipped Rotor 37 nominal: surface 2 then has the reference paper's maximum thickness."""

DEMO_SCENARIO: dict[str, float] = {
    "n_points": 1836,
    "axial_offset_m": -0.1013e-3,
    "circumferential_offset_m": 0.0538e-3,
    "twist_deg": 0.0512,
    "form_amplitude_m": 5e-6,
    "form_waves": 3,
}
"""The demo's simulated scan: the reference paper's point count, measured offsets and twist, a 5 µm form error."""

_SHIPPED_INSTRUMENTS = ("cmm_reference_paper",)
RENAMED_INSTRUMENTS = {"cmm_seed": "cmm_reference_paper"}
"""Old shipped names still accepted (with a DeprecationWarning): ``cmm_seed`` named the reference
paper's CMM and read like the random seed."""


@dataclass(frozen=True, eq=False)
class SectionInspection:
    """What :func:`inspect_section` and :func:`section_demo` computed.

    Attributes
    ----------
    result : SectionUncertainty
        Measured parameters, Monte Carlo, GUM, JCGM 101 §8 validation, per-source budget.
    corrections : tuple of BiasCorrection
        Bias-corrected estimate and interval per parameter (recommended for the max/min ones).
    cloud : PointCloud
        The measured section (metres).
    nominal : str
        Where the nominal came from.
    instrument : str
        Where the instrument came from (a path or a shipped name).
    truth : ndarray, shape (9,) [m, rad], or None
        True parameters (the demo's noise-free scan), else None.
    elapsed_s : float
        Wall time of the Monte Carlo and GUM [s].
    workers : int
        Worker processes used (never changes the result).
    repeats : tuple of str
        Sources of the repeated scans whose spread is in ``result.gum_with_repeatability``
        (empty when none were given).
    curve : NominalCurve or None
        The nominal curve the cloud was evaluated against.
    study : ScenarioStudy or None
        The coverage study run for this cloud (:func:`section_coverage_study`), else None.
    """

    result: SectionUncertainty
    corrections: tuple[BiasCorrection, ...]
    cloud: PointCloud
    nominal: str
    instrument: str
    truth: NDArray[np.float64] | None
    elapsed_s: float
    workers: int
    repeats: tuple[str, ...] = ()
    curve: NominalCurve | None = None
    study: ScenarioStudy | None = None


def _shipped(*parts: str) -> Path:
    return Path(str(resources.files("robocal_uncertainty").joinpath("data", *parts)))


def resolve_instrument(spec: str | None) -> tuple[CmmInstrument, str]:
    """The instrument of a YAML path or a shipped name (None: the reference paper's CMM ``cmm_reference_paper``)."""
    name = "cmm_reference_paper" if spec is None else spec
    if name in RENAMED_INSTRUMENTS and not Path(name).is_file():
        new = RENAMED_INSTRUMENTS[name]
        warnings.warn(f"instrument {name!r} is deprecated: use {new!r}", DeprecationWarning, stacklevel=2)
        name = new
    if name in _SHIPPED_INSTRUMENTS and not Path(name).is_file():
        return load_instrument(_shipped("instruments", f"{name}.yaml")), name
    path = Path(name).expanduser()
    if not path.is_file():
        msg = f"instrument {name!r} is neither a file nor a shipped instrument {list(_SHIPPED_INSTRUMENTS)}"
        raise ConfigError(msg)
    return load_instrument(path), str(path)


def load_section_nominal(spec: str, *, unit: str | None = None) -> NominalCurve:
    """The nominal curve of a file (text, unit stated in it or by `unit`) or a shipped blade.

    Shipped: ``rotor37`` or ``rotor37:K`` (surface K = 1..13, scaled by :data:`ROTOR37_SCALE`),
    ``cascade`` (100 mm chord).
    """
    head, _, rest = spec.partition(":")
    if head == "rotor37" and not Path(spec).is_file():
        try:
            surface = int(rest) if rest else 2
        except ValueError:
            surface = -1
        if not 1 <= surface <= 13:
            msg = f"--nominal rotor37:K needs a surface K in 1..13, got {spec!r}"
            raise ConfigError(msg)
        path = _shipped("blade_sections", "nasa_rotor37_blade_geometry.dat")
        return NominalCurve(read_rotor37_section(path, surface, scale=ROTOR37_SCALE))
    if spec == "cascade" and not Path(spec).is_file():
        return NominalCurve(
            read_cascade_profile(_shipped("blade_sections", "dfvlr_l030-4_cascade_profile.dat"), chord_m=0.1)
        )
    path = Path(spec).expanduser()
    if not path.is_file():
        msg = f"nominal {spec!r} is neither a file nor a shipped blade (rotor37, rotor37:K, cascade)"
        raise InputError(msg)
    section: NominalSection = read_nominal_section(path, unit=unit)
    return NominalCurve(section)


def load_section_cloud(
    spec: str | Path, *, unit: str | None = None, topic: str | None = None, message: int | None = None
) -> PointCloud:
    """A measured section: a bag (``.mcap`` file or rosbag2 directory: PointCloud2 in metres)
    or a CMM text export (unit stated in the file or by `unit`)."""
    path = Path(spec).expanduser()
    if path.is_dir() or path.suffix == ".mcap":
        if unit is not None and unit not in ("m",):
            msg = f"--unit {unit} does not apply to a bag: PointCloud2 points are in metres (REP 103)"
            raise ConfigError(msg)
        return read_point_cloud2(path, topic, message=message)
    if topic is not None or message is not None:
        msg = f"--topic/--message apply to bags only, and {path} is not one"
        raise ConfigError(msg)
    return read_point_cloud(path, unit=unit)


def _run(
    cloud: PointCloud,
    curve: NominalCurve,
    nominal: str,
    instrument: tuple[CmmInstrument, str],
    *,
    trials: int | None,
    adaptive: AdaptiveSettings | None,
    seed: int,
    workers: int,
    progress: ProgressCallback | None,
    truth: NDArray[np.float64] | None,
    method: str,
    repeats: Sequence[PointCloud] = (),
    backend: str = "numpy",
    executor: object | None = None,
) -> SectionInspection:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        msg = f"seed must be an integer >= 0, got {seed!r}"
        raise ConfigError(msg)
    method = canonical_method(method)
    start = time.perf_counter()
    repeat_parameters = _repeat_parameters(cloud, curve, repeats) if repeats else None
    result = section_uncertainty(
        cloud,
        curve,
        seed=seed,
        trials=trials,
        adaptive=adaptive,
        instrument=instrument[0],
        workers=workers,
        chunk_blocks=1 if workers == 1 else 4,
        progress=progress,
        keep_samples=True,
        method=method,
        repeat_parameters=repeat_parameters,
        backend=backend,
        executor=executor,
    )
    return SectionInspection(
        result=result,
        corrections=bias_corrections(result),
        cloud=cloud,
        nominal=nominal,
        instrument=instrument[1],
        truth=truth,
        elapsed_s=time.perf_counter() - start,
        workers=workers,
        repeats=tuple(r.source for r in repeats),
        curve=curve,
    )


REPEAT_TOLERANCE = 0.01
"""Largest relative difference of a repeated scan's chord or maximum thickness from CLOUD's
(both invariant to the part's placement): beyond it the file is not a repeat of this section."""


def _repeat_parameters(cloud: PointCloud, curve: NominalCurve, repeats: Sequence[PointCloud]) -> NDArray[np.float64]:
    """Parameters (k, 9) of the repeated scans, each evaluated as CLOUD is (same nominal, options)."""
    if len(repeats) < 2:
        msg = f"--repeat-scans needs at least 2 repeated scans for a standard deviation, got {len(repeats)}"
        raise ConfigError(msg)
    main = evaluate_section(cloud, curve).parameters
    rows = []
    for scan in repeats:
        try:
            found = evaluate_section(scan, curve).parameters
        except InputError as exc:
            msg = f"repeated scan {scan.source}: {exc}"
            raise InputError(msg) from exc
        for label, a, b in (
            ("chord", found.chord_length, main.chord_length),
            ("maximum thickness", found.max_thickness, main.max_thickness),
        ):
            if abs(a - b) > REPEAT_TOLERANCE * abs(b):
                msg = (
                    f"repeated scan {scan.source}: {label} {a * 1e3:.4f} mm differs from CLOUD's {b * 1e3:.4f} mm "
                    f"by more than {REPEAT_TOLERANCE:.0%}: not a repeat of the same section"
                )
                raise InputError(msg)
        rows.append(found.as_array())
    return np.asarray(rows, dtype=np.float64)


def _load_clouds(
    cloud: str | Path | PointCloud,
    repeat_scans: Sequence[str | Path | PointCloud] | None,
    *,
    unit: str | None,
    topic: str | None,
    message: int | None,
) -> tuple[PointCloud, tuple[PointCloud, ...]]:
    """The measured cloud and the repeated scans, each read as :func:`load_section_cloud` reads."""

    def load(spec: str | Path | PointCloud) -> PointCloud:
        return (
            spec if isinstance(spec, PointCloud) else load_section_cloud(spec, unit=unit, topic=topic, message=message)
        )

    measured = load(cloud)
    if repeat_scans is not None and len(repeat_scans) < 2:
        msg = f"--repeat-scans needs at least 2 repeated scans for a standard deviation, got {len(repeat_scans)}"
        raise ConfigError(msg)
    return measured, tuple(load(spec) for spec in repeat_scans or ())


def inspect_section(
    cloud: str | Path | PointCloud,
    nominal: str | NominalCurve,
    *,
    unit: str | None = None,
    nominal_unit: str | None = None,
    instrument: str | None = None,
    trials: int | None = 1_000_000,
    adaptive: AdaptiveSettings | None = None,
    seed: int = 0,
    workers: int = 1,
    topic: str | None = None,
    message: int | None = None,
    progress: ProgressCallback | None = None,
    method: str = "denoised",
    repeat_scans: Sequence[str | Path | PointCloud] | None = None,
    backend: str = "numpy",
    executor: object | None = None,
) -> SectionInspection:
    """Measure a section's nine parameters and their uncertainty.

    Parameters
    ----------
    cloud : str, Path or PointCloud
        CMM export (x y z [i j k]) or bag with PointCloud2 messages, or a loaded cloud.
    nominal : str or NominalCurve
        Nominal file, shipped blade (``rotor37``, ``rotor37:K``, ``cascade``) or curve.
    unit, nominal_unit : str, optional
        Length unit of the cloud / nominal file when the file states none.
    instrument : str, optional
        Instrument YAML or shipped name; default the reference paper's CMM.
    trials : int or None
        Monte Carlo trials (default 10^6, the reference paper's); None with `adaptive`.
    adaptive : AdaptiveSettings, optional
        JCGM 101 §7.9 adaptive trial count.
    seed : int
        Root seed (>= 0); the result depends only on it, `trials` and the inputs.
    workers : int
        Worker processes (never change the result).
    topic, message : optional
        PointCloud2 topic and message index of a bag (default: its only topic, all messages).
    progress : callable, optional
        ``progress(done, target)`` after each chunk of trial blocks.
    method : str
        ``denoised`` (default) or ``perturbed`` (``seed``: deprecated alias); see
        :func:`~robocal_uncertainty.inspection.section_mc.section_uncertainty`.
    repeat_scans : sequence of str, Path or PointCloud, optional
        k >= 2 repeated scans of the same section (read as `cloud` is, same `unit`, `topic`,
        `message`), evaluated with the same algorithm against the same nominal; their standard
        deviations (ddof 1) enter ``result.gum_with_repeatability`` as the reference paper's u3.
    backend : str
        Trial kernels (``numpy``, ``numba`` or ``auto``; see
        :func:`~robocal_uncertainty.inspection.section_mc.section_uncertainty`): the same
        result to 1e-12 relative; recorded in ``result.backend``.
    executor : object, optional
        Worker pool the trial blocks run on instead of ``workers`` processes started for the
        run (e.g. :class:`~robocal_uncertainty.montecarlo.executor.WorkerPool`'s, started
        early); never changes the result.

    Returns
    -------
    SectionInspection

    Raises
    ------
    ConfigError
        Fewer than 2 repeated scans.
    InputError
        A repeated scan cannot be read or evaluated, or its chord or maximum thickness differs
        from `cloud`'s by more than :data:`REPEAT_TOLERANCE` (not a repeat of this section).
    """
    measured, repeats = _load_clouds(cloud, repeat_scans, unit=unit, topic=topic, message=message)
    if isinstance(nominal, NominalCurve):
        curve, where = nominal, nominal.section.source
    else:
        curve, where = load_section_nominal(nominal, unit=nominal_unit), nominal
    return _run(
        measured,
        curve,
        where,
        resolve_instrument(instrument),
        trials=trials,
        adaptive=adaptive,
        seed=seed,
        workers=workers,
        progress=progress,
        truth=None,
        method=method,
        repeats=repeats,
        backend=backend,
        executor=executor,
    )


def section_demo(
    *,
    trials: int | None = 100_000,
    adaptive: AdaptiveSettings | None = None,
    seed: int = 0,
    workers: int = 1,
    instrument: str | None = None,
    progress: ProgressCallback | None = None,
    method: str = "denoised",
    backend: str = "numpy",
    executor: object | None = None,
) -> SectionInspection:
    """The demo: a simulated CMM scan of the shipped Rotor 37 section, measured with noise.

    The true part is the nominal with the reference paper's offsets (-0.1013 mm, 0.0538 mm), twist
    0.0512° and a 5 µm three-wave form error (:data:`DEMO_SCENARIO`); 1 836 points are
    scanned and one draw of the instrument errors (seeded by `seed`) is added, as a real scan
    would carry. ``truth`` holds the true parameters (those of the noise-free scan).
    ``backend`` and ``executor`` as for :func:`inspect_section`.
    """
    from robocal_uncertainty.core.instruments.cmm import point_displacements
    from robocal_uncertainty.inspection.section_mc import section_sources

    curve = load_section_nominal("rotor37")
    scenario = DEMO_SCENARIO
    true_scan = simulate_section_scan(
        curve,
        int(scenario["n_points"]),
        offset=(float(scenario["axial_offset_m"]), float(scenario["circumferential_offset_m"])),
        twist=math.radians(float(scenario["twist_deg"])),
        form_amplitude=float(scenario["form_amplitude_m"]),
        form_waves=int(scenario["form_waves"]),
    )
    inst = resolve_instrument(instrument)
    clean = evaluate_section(true_scan, curve)
    sources = section_sources(clean, inst[0], probe_vectors=true_scan.probe_vectors)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2**31,)))
    order = np.argsort(clean.order)
    shift = point_displacements(sources, rng)[0][order]
    noisy = true_scan.points.copy()
    noisy[:, :2] += shift
    measured = PointCloud(noisy, true_scan.probe_vectors, "demo: simulated 1836-point CMM scan of Rotor 37")
    return _run(
        measured,
        curve,
        f"rotor37 (shipped, surface 2 x {ROTOR37_SCALE})",
        inst,
        trials=trials,
        adaptive=adaptive,
        seed=seed,
        workers=workers,
        progress=progress,
        truth=clean.parameters.as_array(),
        method=method,
        backend=backend,
        executor=executor,
    )


def section_coverage_study(
    run: SectionInspection,
    scans: int,
    *,
    seed: int = 23,
    trials: int = 2000,
    workers: int = 1,
    dask: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    estimate: Callable[[float], None] | None = None,
    backend: str = "numpy",
) -> SectionInspection:
    """`run` with the coverage study of its own cloud: ``scans`` simulated scans per family.

    The study simulates the cloud's nominal, its point layout (registered nominal-curve
    parameters) and probe vectors, its instrument, its offsets and twist, and the four form
    families scaled to its denoised form level
    (:func:`~robocal_uncertainty.inspection.coverage_study.scenario_from_cloud`), runs method
    ``denoised`` on each scan and applies the coverage rule
    (:mod:`~robocal_uncertainty.inspection.coverage_rule`). The report then states "verified
    for this part, layout and instrument" from that study instead of the stored ones.

    Parameters
    ----------
    run : SectionInspection
        A method-``denoised`` inspection (:func:`inspect_section` or :func:`section_demo`).
    scans : int
        Scans per family (>= 1).
    seed : int
        Root seed of the study (the stored study's: 23).
    trials : int
        Monte Carlo trials per scan.
    workers, dask
        Where the scans run (never changes the outcome).
    progress, estimate
        ``progress(done, total)`` per scan; ``estimate(seconds)`` after the first scan.
    backend : str
        Trial kernels of the scans' Monte Carlo (``numpy``, ``numba``, ``auto``): never changes
        an outcome beyond rounding; recorded in the study.

    Returns
    -------
    SectionInspection
        `run` with ``study`` set.
    """
    if run.result.method != "denoised":
        msg = "--coverage-study runs method denoised on every simulated scan: give --method denoised"
        raise ConfigError(msg)
    if run.curve is None:
        msg = "this inspection carries no nominal curve to simulate"
        raise ConfigError(msg)
    scenario = scenario_from_cloud(
        run.cloud,
        run.curve,
        run.result.instrument,
        label=f"{run.cloud.n_points} points of {run.cloud.source} on {run.nominal}, instrument {run.instrument}",
    )
    study = run_scenario_study(
        scenario,
        scans,
        trials=trials,
        root_seed=seed,
        workers=workers,
        dask=dask,
        progress=progress,
        estimate=estimate,
        backend=backend,
    )
    return dataclasses.replace(run, study=study)
