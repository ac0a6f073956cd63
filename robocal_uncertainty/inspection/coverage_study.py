"""Coverage study of the section intervals over families of simulated parts.

Each scan of a family is one simulated part: the shipped Rotor 37 section at the reference paper's size
(:data:`ROTOR37_SCALE`), 1 836 points (denser at the edges), the reference paper's offsets and twist, a
smooth form error and, for the local families, one local feature; one draw of the reference paper's CMM
errors is added, as a real scan carries. The method under test sees only the noisy scan. The
truth is the package's parameter extraction (:func:`~.section.evaluate_section`) on the
noise-free scan of the same part, which knows nothing of the denoising or the Monte Carlo.

Families (:data:`FAMILIES`; every draw from the scan's own seeded stream):

``smooth``
    A sinusoidal form error of 2, 3, 5, 8 or 13 waves around the contour (wavelength 405 mm to
    62 mm), amplitude U(2, 10) µm, random phase.
``side``
    The demo's 5 µm three-wave form (random phase) and one bump or dent on the pressure or the
    suction side, at least 15 mm from either edge: amplitude U(1, 10) µm, full width U(1, 20) mm
    along the contour, raised-cosine shape.
``edge``
    As ``side``, the feature centred within ±10 mm (along the contour) of the leading- or the
    trailing-edge extreme point: on the edge arc, across its junction with a side, or just
    beside it.
``erosion``
    As ``side``, an edge flattened: material removed (inward) by U(1, 10) µm over a plateau of
    half the feature's width U(1, 20) mm, with raised-cosine flanks, centred within ±2 mm of the
    leading- or trailing-edge extreme point.

:func:`study_scan` gives, per scan, whether each parameter's stated 95 % interval (method
``denoised``, the max/min parameters widened to the roughness envelope of :mod:`.resolution`, clipped at 0
for the max/min parameters, as the report states it) holds the truth,
and whether the per-scan residual check (:class:`~.denoise.ResidualCheck`) flagged the scan.

Scenario
--------
Everything the study simulates besides the families is a :class:`StudyScenario`: the nominal
curve, the point layout (nominal-curve parameters of the scan points and their probe vectors),
the instrument, the offsets and twist, and a form scale. :func:`rotor37_scenario` is the stored
study's (the defaults above; ``form_scale`` 1). :func:`scenario_from_cloud` makes one of a
user's measured cloud, so that a study speaks for *that* part, layout and instrument:

- nominal: the user's nominal curve;
- layout: the registered nominal-curve parameters of the measured points (their feet on the
  nominal, in contour order) and, when the cloud has them, its probe vectors, which then also
  orient the probing error and are passed to the method as the user's export passes them;
- instrument: the user's :class:`~robocal_uncertainty.core.instruments.cmm.CmmInstrument` (noise draw and method alike);
- offsets and twist: the measured cloud's (the part sits where the user's part sits);
- form scale: ``max(1, r / STUDY_FORM_RMS)``, ``r`` the root mean square of the cloud's
  denoised normal deviations (:attr:`~.denoise.DenoisedCloud.deviation`, the form the
  denoising found, offsets and twist registered out) and :data:`STUDY_FORM_RMS` that of the
  stored families' base form (5 µm, three waves: 3.54 µm). Every form and feature amplitude of
  the families is multiplied by it; widths, positions and wave counts are not. It is never
  below 1: a smoother part than the stored study's is still tested over the stored amplitudes
  (1-10 µm features, 2-10 µm smooth forms), never over smaller ones only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache, cached_property
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.instruments.cmm import CmmInstrument, point_displacements
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.inspection.bias_correction import MAX_MIN_PARAMETERS
from robocal_uncertainty.inspection.coverage_rule import FamilyCounts, FamilyCoverage, family_cells
from robocal_uncertainty.inspection.denoise import denoise_section
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud, read_rotor37_section
from robocal_uncertainty.inspection.section import PARAMETER_NAMES, evaluate_section
from robocal_uncertainty.inspection.section_mc import prepare_trials, section_sources
from robocal_uncertainty.inspection.simulate import scan_parameters, simulate_section_scan
from robocal_uncertainty.kernels.registry import BackendInfo
from robocal_uncertainty.kernels.section_kernels import resolve_section_backend
from robocal_uncertainty.montecarlo.engine import run_trials
from robocal_uncertainty.montecarlo.summary import summarize

__all__ = [
    "FAMILIES",
    "ROTOR37_SCALE",
    "STUDY_FORM_RMS",
    "Feature",
    "Part",
    "ScanOutcome",
    "ScenarioStudy",
    "StudyProgress",
    "StudyRow",
    "StudyScenario",
    "draw_part",
    "family_counts",
    "feature_deviation",
    "rotor37_scenario",
    "run_scenario_study",
    "run_study",
    "scenario_from_cloud",
    "study_scan",
    "summarize_study",
]

ROTOR37_SCALE = 7.14
"""Rotor 37 surface 2 scaled to the reference paper's blade (maximum thickness 30.37 mm)."""

FAMILIES: tuple[str, ...] = ("smooth", "side", "edge", "erosion")
"""Scenario families of the study (see the module docstring)."""

OFFSET = (-0.1013e-3, 0.0538e-3)
"""The reference paper's measured axial and circumferential offsets [m]."""
TWIST = math.radians(0.0512)
"""The reference paper's measured twist [rad]."""
N_POINTS = 1836
"""The reference paper's point count."""

_SMOOTH_WAVES = (2, 3, 5, 8, 13)

STUDY_FORM_RMS = 5e-6 / math.sqrt(2.0)
"""Root mean square [m] of the stored families' base form (5 µm, three waves): the reference
of a scenario's form scale (see the module docstring)."""

_SIDE_MARGIN = 15e-3
"""Distance [m] of a ``side`` feature's flank from either edge extreme point (at most a quarter
of the side's length, for a short side)."""


@dataclass(frozen=True)
class Feature:
    """One local form feature along the outward normal.

    Attributes
    ----------
    kind : str
        ``bump`` (outward), ``dent`` (inward) or ``erosion`` (inward plateau).
    centre : float
        Nominal-curve parameter of its centre [m].
    amplitude : float
        Height (bump) or depth (dent, erosion) [m], > 0.
    width : float
        Full width along the contour [m].
    """

    kind: str
    centre: float
    amplitude: float
    width: float


@dataclass(frozen=True)
class Part:
    """A simulated part: smooth form error plus local features."""

    family: str
    form_amplitude: float
    form_waves: int
    form_phase: float
    features: tuple[Feature, ...]

    def describe(self) -> str:
        """One line, lengths in µm and mm."""
        text = f"{self.form_amplitude * 1e6:.1f} um {self.form_waves}-wave form"
        for f in self.features:
            text += f", {f.kind} {f.amplitude * 1e6:.1f} um x {f.width * 1e3:.1f} mm at u = {f.centre * 1e3:.1f} mm"
        return text


def feature_deviation(u: NDArray[np.float64], features: Sequence[Feature], period: float) -> NDArray[np.float64]:
    """Normal deviation [m] of the features at nominal-curve parameters ``u`` [m] (closed contour)."""
    out = np.zeros_like(np.asarray(u, dtype=np.float64))
    for f in features:
        d = (np.asarray(u) - f.centre + period / 2) % period - period / 2
        if f.kind in ("bump", "dent"):
            shape = np.where(np.abs(d) < f.width / 2, 0.5 * (1.0 + np.cos(2 * math.pi * d / f.width)), 0.0)
            out += (1.0 if f.kind == "bump" else -1.0) * f.amplitude * shape
        elif f.kind == "erosion":
            plateau, flank = f.width / 4, f.width / 4
            beyond = np.clip((np.abs(d) - plateau) / flank, 0.0, 1.0)
            out -= f.amplitude * 0.5 * (1.0 + np.cos(math.pi * beyond))
        else:
            msg = f"unknown feature kind {f.kind!r}"
            raise ValueError(msg)
    return out


@cache
def _curve() -> NominalCurve:
    """The shipped Rotor 37 surface 2 at :data:`ROTOR37_SCALE` (the app's ``rotor37`` nominal)."""
    path = resources.files("robocal_uncertainty").joinpath("data", "blade_sections", "nasa_rotor37_blade_geometry.dat")
    return NominalCurve(read_rotor37_section(Path(str(path)), 2, scale=ROTOR37_SCALE))


@dataclass(frozen=True, eq=False)
class StudyScenario:
    """What a coverage study simulates besides the families (see the module docstring).

    Attributes
    ----------
    curve : NominalCurve
        Nominal section.
    parameters : ndarray, shape (n,) [m]
        Nominal-curve parameters of the scan points, in scan order (the point layout).
    probe_vectors : ndarray, shape (n, 3), or None
        Probe vectors of the scan points in scan order; None: the outward normals turned by the
        twist (the simulated scanner's).
    instrument : CmmInstrument
        The CMM whose errors every scan carries and the method assumes.
    offset : tuple of float
        True axial and circumferential offsets [m].
    twist : float
        True twist [rad].
    form_scale : float
        Factor (>= 1) on every family's form and feature amplitudes.
    probe_in_method : bool
        Whether the method is given the probe vectors (a cloud export with i j k) or works with
        the nominal normals (the stored study: its scans are plain point arrays).
    label : str
        One line for reports.
    form_rms : float
        Root mean square of the scenario cloud's denoised deviations [m] (nan for the stored study).
    """

    curve: NominalCurve
    parameters: NDArray[np.float64]
    probe_vectors: NDArray[np.float64] | None
    instrument: CmmInstrument
    offset: tuple[float, float]
    twist: float
    form_scale: float = 1.0
    probe_in_method: bool = False
    label: str = ""
    form_rms: float = math.nan

    @property
    def n_points(self) -> int:
        """Points per scan."""
        return int(self.parameters.shape[0])

    @cached_property
    def landmarks(self) -> tuple[float, float]:
        """Nominal-curve parameters of the leading- and trailing-edge extreme points [m]."""
        clean = evaluate_section(
            simulate_section_scan(self.curve, self.n_points, parameters=self.parameters), self.curve
        )
        seg = clean.segmentation
        u = clean.registration.parameter
        return float(u[seg.leading_edge_point]), float(u[seg.trailing_edge_point])


@cache
def rotor37_scenario() -> StudyScenario:
    """The stored study's scenario: Rotor 37 at the reference paper's size, 1 836 points, the reference paper's CMM."""
    curve = _curve()
    return StudyScenario(
        curve=curve,
        parameters=scan_parameters(curve, N_POINTS),
        probe_vectors=None,
        instrument=CmmInstrument(),
        offset=OFFSET,
        twist=TWIST,
        label=f"Rotor 37 surface 2 x {ROTOR37_SCALE}, {N_POINTS} points, the reference paper's CMM",
    )


def scenario_from_cloud(
    cloud: PointCloud, curve: NominalCurve, instrument: CmmInstrument, *, label: str = ""
) -> StudyScenario:
    """The scenario of a measured cloud: its nominal, layout, probe vectors, instrument, placement
    and form level (see the module docstring).

    Parameters
    ----------
    cloud : PointCloud
        The measured section.
    curve : NominalCurve
        Its nominal.
    instrument : CmmInstrument
        The CMM that measured it.
    label : str
        One line for reports (default: the cloud's point count and instrument name).

    Returns
    -------
    StudyScenario
    """
    evaluation = evaluate_section(cloud, curve)
    probe = None if cloud.probe_vectors is None else np.asarray(cloud.probe_vectors, dtype=np.float64)
    sources = section_sources(evaluation, instrument, probe_vectors=probe)
    denoised = denoise_section(evaluation, sources, curve.period)
    rms = float(np.sqrt(np.mean(denoised.deviation**2)))
    measured = evaluation.parameters
    return StudyScenario(
        curve=curve,
        parameters=np.asarray(evaluation.registration.parameter, dtype=np.float64).copy(),
        probe_vectors=None if probe is None else probe[evaluation.order].copy(),
        instrument=instrument,
        offset=(float(measured.axial_offset), float(measured.circumferential_offset)),
        twist=float(measured.twist_angle),
        form_scale=max(1.0, rms / STUDY_FORM_RMS),
        probe_in_method=probe is not None,
        label=label or f"{evaluation.points.shape[0]} points as measured, instrument {instrument.name}",
        form_rms=rms,
    )


def _landmarks() -> tuple[float, float]:
    """The stored scenario's leading- and trailing-edge extreme points [m]."""
    return rotor37_scenario().landmarks


def draw_part(family: str, rng: np.random.Generator, scenario: StudyScenario | None = None) -> Part:
    """A random part of ``family`` (see the module docstring) on ``scenario`` (default the stored one)."""
    scene = rotor37_scenario() if scenario is None else scenario
    period = scene.curve.period
    le, te = scene.landmarks
    scale = scene.form_scale
    if family == "smooth":
        return Part(
            family,
            float(rng.uniform(2e-6, 10e-6)) * scale,
            int(rng.choice(_SMOOTH_WAVES)),
            float(rng.uniform(0, 2 * math.pi)),
            (),
        )
    if family not in FAMILIES:
        msg = f"family must be one of {list(FAMILIES)}, got {family!r}"
        raise ValueError(msg)
    phase = float(rng.uniform(0, 2 * math.pi))
    amplitude = float(rng.uniform(1e-6, 10e-6)) * scale
    width = float(rng.uniform(1e-3, 20e-3))
    edge = le if rng.random() < 0.5 else te
    if family == "side":
        kind = "bump" if rng.random() < 0.5 else "dent"
        # One side runs LE -> TE, the other TE -> LE (increasing u, modulo the period).
        start, stop = (le, te) if rng.random() < 0.5 else (te, le)
        if stop < start:  # the side crosses the nominal's parameter origin
            stop += period
        side = stop - start
        margin = min(_SIDE_MARGIN, side / 4) + width / 2
        if stop - margin <= start + margin:
            msg = f"a side of {side * 1e3:.1f} mm is too short for the side family's features (up to 20 mm wide)"
            raise InputError(msg)
        centre = float(rng.uniform(start + margin, stop - margin)) % period
    elif family == "edge":
        kind = "bump" if rng.random() < 0.5 else "dent"
        centre = float(edge + rng.uniform(-10e-3, 10e-3)) % period
    else:
        kind = "erosion"
        centre = float(edge + rng.uniform(-2e-3, 2e-3)) % period
    return Part(family, 5e-6 * scale, 3, phase, (Feature(kind, centre, amplitude, width),))


@dataclass(frozen=True)
class ScanOutcome:
    """One scan of the study.

    Attributes
    ----------
    family : str
        Scenario family.
    index : int
        Scan index in the family.
    part : Part
        The simulated part.
    inside : ndarray of bool, shape (9,)
        Whether each stated 95 % interval holds the truth (:data:`~.section.PARAMETER_NAMES`).
    flagged : bool
        Whether the residual check flagged the scan (interval not verified for this cloud).
    p_value : float
        The check's p-value.
    """

    family: str
    index: int
    part: Part
    inside: NDArray[np.bool_]
    flagged: bool
    p_value: float


def study_scan(
    family: str,
    index: int,
    *,
    trials: int = 2000,
    root_seed: int = 23,
    scenario: StudyScenario | None = None,
    backend: str = "numpy",
) -> ScanOutcome:
    """Simulate scan ``index`` of ``family``, run method ``denoised`` on it, compare with the truth.

    The part, the instrument-noise draw and the Monte Carlo seed come from
    ``SeedSequence(root_seed, spawn_key=(family index, index))``; ``scenario`` (default
    :func:`rotor37_scenario`, the stored study's) gives the nominal, layout, instrument,
    placement and form scale. ``backend`` runs the scan's Monte Carlo (``numpy`` or ``numba``,
    :mod:`robocal_uncertainty.kernels.section_kernels`): the same draws, values equal to rounding.
    """
    scene = rotor37_scenario() if scenario is None else scenario
    curve = scene.curve
    family_index = FAMILIES.index(family) if family in FAMILIES else -1
    part_seq, noise_seq, mc_seq = np.random.SeedSequence(root_seed, spawn_key=(family_index, index)).spawn(3)
    part = draw_part(family, np.random.default_rng(part_seq), scene)
    true_scan = simulate_section_scan(
        curve,
        scene.n_points,
        offset=scene.offset,
        twist=scene.twist,
        form_amplitude=part.form_amplitude,
        form_waves=part.form_waves,
        form_phase=part.form_phase,
        deviation=(lambda u: feature_deviation(u, part.features, curve.period)) if part.features else None,
        parameters=scene.parameters,
    )
    if scene.probe_vectors is not None:
        true_scan = PointCloud(true_scan.points, scene.probe_vectors, true_scan.source)
    clean = evaluate_section(true_scan, curve)
    truth = clean.parameters.as_array()
    sources = section_sources(clean, scene.instrument, probe_vectors=true_scan.probe_vectors)
    noisy = clean.points + point_displacements(sources, np.random.default_rng(noise_seq))[0]
    measured: PointCloud | NDArray[np.float64] = noisy
    if scene.probe_in_method and true_scan.probe_vectors is not None:
        # As the user's export: the probe vectors travel with the points (here in contour order).
        flat = np.column_stack([noisy, np.zeros(noisy.shape[0])])
        measured = PointCloud(flat, true_scan.probe_vectors[clean.order], true_scan.source)
    setup = prepare_trials(measured, curve, instrument=scene.instrument, method="denoised", backend=backend)
    seed = int(mc_seq.generate_state(1)[0])
    samples = run_trials(setup.trials(backend=backend), seed=seed, n_trials=trials, block_size=trials).samples
    outputs = summarize(samples, 0.95, bins=10).outputs
    envelope = setup.envelope(seed, 0.95)
    inside = np.empty(len(PARAMETER_NAMES), dtype=bool)
    for j, (name, out) in enumerate(zip(PARAMETER_NAMES, outputs)):
        low, high = out.probabilistically_symmetric.low, out.probabilistically_symmetric.high
        if envelope is not None:  # the max/min parameters' roughness envelope, as the report states it
            low, high = envelope.widen(name, low, high)
        if name in MAX_MIN_PARAMETERS:  # the report clips the non-negative lengths at 0
            low, high = max(low, 0.0), max(high, 0.0)
        inside[j] = low <= truth[j] <= high
    return ScanOutcome(family, index, part, inside, bool(setup.check.flagged), float(setup.check.p_value))


def _scan_job(
    family: str,
    index: int,
    trials: int,
    root_seed: int,
    scenario: StudyScenario | None = None,
    backend: str = "numpy",
) -> ScanOutcome:
    return study_scan(family, index, trials=trials, root_seed=root_seed, scenario=scenario, backend=backend)


StudyProgress = Callable[[int, int], None]
"""``progress(done, total)`` after each finished scan."""


def run_study(
    families: Sequence[str] = FAMILIES,
    scans: int = 40,
    *,
    trials: int = 2000,
    root_seed: int = 23,
    workers: int = 1,
    first: int = 0,
    scenario: StudyScenario | None = None,
    executor: object | None = None,
    dask: str | None = None,
    progress: StudyProgress | None = None,
    backend: str = "numpy",
) -> list[ScanOutcome]:
    """Scans ``first .. first + scans - 1`` of every family on ``scenario`` (default the stored one).

    Every scan draws from its own stream (:func:`study_scan`): the outcomes are the same
    whatever ``workers``, ``executor`` or ``dask`` (as for
    :func:`~robocal_uncertainty.montecarlo.executor.open_executor`) runs them on, and come back
    in family, then scan order. ``backend`` (a resolved name, ``numpy`` or ``numba``) runs the
    denoising and the trials; the backends agree to 1e-12 with the same draws.
    """
    jobs = [(f, k) for f in families for k in range(first, first + scans)]
    return _run_jobs(jobs, trials, root_seed, scenario, workers, executor, dask, progress, backend=backend)


def _run_jobs(
    jobs: Sequence[tuple[str, int]],
    trials: int,
    root_seed: int,
    scenario: StudyScenario | None,
    workers: int,
    executor: object | None,
    dask: str | None,
    progress: StudyProgress | None,
    *,
    backend: str = "numpy",
) -> list[ScanOutcome]:
    """Run (family, scan) jobs in this process or on an executor; outcomes in job order."""
    from robocal_uncertainty.montecarlo.executor import open_executor

    out: list[ScanOutcome] = []
    with open_executor(workers=workers, executor=executor, dask=dask) as runner:
        if runner is None:
            for family, index in jobs:
                out.append(_scan_job(family, index, trials, root_seed, scenario, backend))
                if progress is not None:
                    progress(len(out), len(jobs))
            return out
        futures = [
            runner.submit(_scan_job, family, index, trials, root_seed, scenario, backend) for family, index in jobs
        ]
        for future in futures:
            out.append(future.result())
            if progress is not None:
                progress(len(out), len(jobs))
    return out


@dataclass(frozen=True)
class StudyRow:
    """Coverage of one parameter in one family.

    Attributes
    ----------
    family, parameter : str
        Scenario family and parameter name.
    scans : int
        Scans of the family.
    flagged : int
        Scans the residual check flagged.
    coverage_all : float
        Fraction of all scans whose interval holds the truth.
    coverage_unflagged : float
        The same over the scans the check did not flag (nan if all were flagged).
    u_unflagged : float
        Binomial standard uncertainty of ``coverage_unflagged`` at 95 %: sqrt(0.95·0.05/N).
    """

    family: str
    parameter: str
    scans: int
    flagged: int
    coverage_all: float
    coverage_unflagged: float
    u_unflagged: float


def summarize_study(outcomes: Sequence[ScanOutcome]) -> list[StudyRow]:
    """Per family and parameter: coverage over all and over the unflagged scans."""
    rows = []
    for family in dict.fromkeys(o.family for o in outcomes):
        chosen = [o for o in outcomes if o.family == family]
        inside = np.array([o.inside for o in chosen])
        flagged = np.array([o.flagged for o in chosen])
        kept = inside[~flagged]
        for j, name in enumerate(PARAMETER_NAMES):
            n_kept = int(kept.shape[0])
            rows.append(
                StudyRow(
                    family=family,
                    parameter=name,
                    scans=len(chosen),
                    flagged=int(flagged.sum()),
                    coverage_all=float(inside[:, j].mean()),
                    coverage_unflagged=float(kept[:, j].mean()) if n_kept else math.nan,
                    u_unflagged=math.sqrt(0.95 * 0.05 / n_kept) if n_kept else math.nan,
                )
            )
    return rows


def family_counts(outcomes: Sequence[ScanOutcome]) -> dict[str, FamilyCounts]:
    """Per family: (scans, flagged, inside per parameter among the unflagged, inside among all)."""
    counts: dict[str, FamilyCounts] = {}
    for family in dict.fromkeys(o.family for o in outcomes):
        chosen = [o for o in outcomes if o.family == family]
        inside = np.array([o.inside for o in chosen], dtype=bool).reshape(len(chosen), len(PARAMETER_NAMES))
        flagged = np.array([o.flagged for o in chosen], dtype=bool)
        counts[family] = (
            len(chosen),
            int(flagged.sum()),
            tuple(int(v) for v in inside[~flagged].sum(axis=0)),
            tuple(int(v) for v in inside.sum(axis=0)),
        )
    return counts


@dataclass(frozen=True)
class ScenarioStudy:
    """A family study run for one scenario (a user's part, layout and instrument) and its verdict.

    Attributes
    ----------
    label : str
        The scenario in one line.
    n_points : int
        Points per simulated scan (the layout's).
    nominal_length : float
        Contour length of the nominal [m].
    instrument : CmmInstrument
        The instrument simulated and assumed.
    form_scale : float
        Factor on the families' amplitudes (>= 1).
    form_rms : float
        Root mean square of the measured cloud's denoised deviations [m] (nan: stored study).
    probe_vectors : bool
        Whether the layout carried the cloud's probe vectors.
    root_seed : int
        Root seed of the study's streams.
    scans : int
        Scans per family.
    trials : int
        Monte Carlo trials per scan.
    families : tuple of str
        Families run.
    elapsed_s : float
        Wall time of the study [s].
    workers : int
        Worker processes (never change the outcome).
    counts : dict
        Per family, :data:`~.coverage_rule.FamilyCounts`.
    cells : dict
        ``cells[family][parameter]`` with the Holm-adjusted verdict (:func:`~.coverage_rule.family_cells`).
    backend : BackendInfo or None
        Trial kernels of the scans' Monte Carlo (None when not recorded).
    """

    label: str
    n_points: int
    nominal_length: float
    instrument: CmmInstrument
    form_scale: float
    form_rms: float
    probe_vectors: bool
    root_seed: int
    scans: int
    trials: int
    families: tuple[str, ...]
    elapsed_s: float
    workers: int
    counts: dict[str, FamilyCounts]
    cells: dict[str, dict[str, FamilyCoverage]]
    backend: BackendInfo | None = None

    def lowest(self, name: str) -> float:
        """Lowest coverage of parameter `name` over the families' unflagged scans (nan if none)."""
        values = [c[name].coverage for c in self.cells.values() if c[name].scans > c[name].flagged]
        return min(values) if values else math.nan

    def verified(self, name: str) -> bool:
        """Whether every family's cell of `name` passes the rule (:attr:`~.coverage_rule.FamilyCoverage.consistent`)."""
        return bool(self.cells) and all(c[name].consistent for c in self.cells.values())

    @property
    def verified_all(self) -> bool:
        """Whether every parameter is verified."""
        return all(self.verified(name) for name in PARAMETER_NAMES)

    @property
    def total_scans(self) -> int:
        """Scans over all families."""
        return self.scans * len(self.families)


def _check_study(scans: int, root_seed: int, families: Sequence[str]) -> tuple[str, ...]:
    """The families of a valid study request (InputError naming the problem otherwise)."""
    if isinstance(scans, bool) or not isinstance(scans, int) or scans < 1:
        msg = f"coverage study scans must be an integer >= 1, got {scans!r}"
        raise InputError(msg)
    if isinstance(root_seed, bool) or not isinstance(root_seed, int) or root_seed < 0:
        msg = f"coverage study seed must be an integer >= 0, got {root_seed!r}"
        raise InputError(msg)
    chosen = tuple(families)
    unknown = [f for f in chosen if f not in FAMILIES]
    if unknown or not chosen:
        msg = f"families must be a non-empty subset of {list(FAMILIES)}, got {list(chosen)}"
        raise InputError(msg)
    return chosen


def run_scenario_study(
    scenario: StudyScenario,
    scans: int,
    *,
    families: Sequence[str] = FAMILIES,
    trials: int = 2000,
    root_seed: int = 23,
    workers: int = 1,
    executor: object | None = None,
    dask: str | None = None,
    progress: StudyProgress | None = None,
    estimate: Callable[[float], None] | None = None,
    backend: str = "numpy",
) -> ScenarioStudy:
    """The family study of `scenario`: `scans` scans per family, then the verdict per cell.

    Parameters
    ----------
    scenario : StudyScenario
        What to simulate (:func:`scenario_from_cloud` for a user's cloud).
    scans : int
        Scans per family (>= 1; at least :data:`~.coverage_rule.MIN_STUDY_SCANS` unflagged ones
        per family are needed before anything can be verified).
    families : sequence of str
        Families to run (default all four).
    trials : int
        Monte Carlo trials per scan (the stored study: 2 000).
    root_seed : int
        Root seed; the outcome depends only on it, `scans`, `trials` and the scenario.
    workers, executor, dask
        Where the scans run (:func:`~robocal_uncertainty.montecarlo.executor.open_executor`).
    progress : callable, optional
        ``progress(done, total)`` after each scan.
    estimate : callable, optional
        Called with the seconds the first scan took (run first, in this process) before the
        others start: for an expected time.
    backend : str
        Trial kernels of every scan's Monte Carlo: ``numpy``, ``numba`` or ``auto``
        (:func:`~robocal_uncertainty.kernels.section_kernels.resolve_section_backend`); recorded.

    Returns
    -------
    ScenarioStudy
    """
    chosen = _check_study(scans, root_seed, families)
    kernels = resolve_section_backend(backend)
    start = time.perf_counter()
    first = study_scan(chosen[0], 0, trials=trials, root_seed=root_seed, scenario=scenario, backend=kernels.name)
    if estimate is not None:
        estimate(time.perf_counter() - start)
    total = scans * len(chosen)
    if progress is not None:
        progress(1, total)
    rest: list[ScanOutcome] = []
    jobs = [(f, k) for f in chosen for k in range(scans)][1:]
    if jobs:

        def shifted(done: int, _: int) -> None:
            if progress is not None:
                progress(done + 1, total)

        # Every job is one (family, scan) of the same streams run_study would use.
        rest = _run_jobs(jobs, trials, root_seed, scenario, workers, executor, dask, shifted, backend=kernels.name)
    outcomes = [first, *rest]
    counts = family_counts(outcomes)
    return ScenarioStudy(
        label=scenario.label,
        n_points=scenario.n_points,
        nominal_length=float(scenario.curve.period),
        instrument=scenario.instrument,
        form_scale=scenario.form_scale,
        form_rms=scenario.form_rms,
        probe_vectors=scenario.probe_vectors is not None,
        root_seed=root_seed,
        scans=scans,
        trials=trials,
        families=chosen,
        elapsed_s=time.perf_counter() - start,
        workers=workers,
        counts=counts,
        cells=family_cells(counts, PARAMETER_NAMES),
        backend=kernels,
    )
