"""Benchmark: 10^6 Monte Carlo trials of the nine blade-section parameters on 1 836 points, per backend.

Scenario (issue 9 / the second reference paper): NASA Rotor 37 surface 2 scaled by 7.14 (maximum thickness 30.37 mm,
the reference paper's 30.365 mm; chord 397 mm), a simulated 1 836-point scan with the reference paper's measured
offsets (-0.1013 mm, 0.0538 mm) and twist (0.0512°) and a 5 µm three-wave form error, measured
with the reference paper's CMM (config/instruments/cmm_reference_paper.yaml). The naive baseline runs the full
algorithm (registration, segmentation, thickness, chord, profile) per trial on the same draws;
its time for 10^6 trials is extrapolated from ``--naive`` trials.

Each backend of the section trial (``--backends``, default numpy and numba where installed;
:mod:`robocal_uncertainty.kernels.section_kernels`) runs the same trials from the same seed in
this one run: the time of the trials alone (wall; CPU and CPU per trial with one worker, where
the CPU time is this process's own, the fairer figure on a shared machine), of
the statements after them (GUM budget, roughness envelope, summaries), the ratio against
numpy's trials, and the largest difference of the nine Monte Carlo estimates and standard
uncertainties from numpy's, relative to the parameter's magnitude. The cloud's preparation
(evaluation, denoising, residual check) is shared and timed once.

Run: ``python benchmarks/bench_section_mc.py [--trials 1000000] [--workers 2] [--naive 100]
[--method denoised|perturbed] [--backends numpy numba]`` (default method ``denoised``, the CLI's:
the Monte Carlo of the error around the denoised cloud; its MC mean is the bias-corrected
estimate, the value column the measured one). Prints the times, peak memory (this process and its
workers) and the last backend's results next to the reference paper's.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.core.instruments.cmm import CmmInstrument, load_instrument
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import read_rotor37_section
from robocal_uncertainty.inspection.section import PARAMETER_NAMES
from robocal_uncertainty.inspection.section_mc import (
    SectionUncertainty,
    TrialSetup,
    _section_result,
    full_section_trials,
    prepare_trials,
)
from robocal_uncertainty.inspection.simulate import simulate_section_scan
from robocal_uncertainty.kernels import available_backends
from robocal_uncertainty.kernels.section_kernels import SECTION_BACKENDS, resolve_section_backend, warm_up
from robocal_uncertainty.montecarlo.engine import run_trials

ROOT = Path(__file__).resolve().parents[1]
ROTOR37 = ROOT / "test" / "inspection" / "data" / "nasa_rotor37_blade_geometry.dat"
INSTRUMENT = ROOT / "config" / "instruments" / "cmm_reference_paper.yaml"

# The reference paper's published Monte Carlo results (value, standard uncertainty) in mm / µm
# (twist: degrees / millidegrees);
# its Table 1 (chord) and Table 2 (profile) survive only as captions, so only the GUM chord
# budget is known for the chord: U95 = 4.686 µm with u3 = 2.087 µm repeatability.
PAPER = {
    "max_thickness": (30.365, 1.76),
    "axial_offset": (-0.1013, 0.089),
    "circumferential_offset": (0.0538, 0.045),
    "twist_angle": (0.0512, 0.31),
}


def peak_mib() -> tuple[float, float]:
    """Peak resident memory of this process and of its largest finished child [MiB]."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return own, children


def cpu_seconds() -> float:
    """CPU time of this process and its finished children [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run_backend(
    prepared: TrialSetup, curve: NominalCurve, instrument: CmmInstrument, backend: str, args: argparse.Namespace
) -> tuple[SectionUncertainty, float, float, float]:
    """Trials and statements on `backend`: (result, trials wall s, trials CPU s, statements s)."""
    block = prepared.trials(backend=backend)
    if backend == "numba":
        warm_up()  # compiled or loaded from the disk cache before the clock starts (printed when compiled)
    start, cpu = time.perf_counter(), cpu_seconds()
    run = run_trials(
        block, seed=args.seed, n_trials=args.trials, workers=args.workers, chunk_blocks=1 if args.workers == 1 else 4
    )
    trials_s, trials_cpu = time.perf_counter() - start, cpu_seconds() - cpu
    start = time.perf_counter()
    result = _section_result(
        prepared, block, run, 0.95, instrument, None, curve, bins=100, keep_samples=False, repeats=None
    )
    return result, trials_s, trials_cpu, time.perf_counter() - start


def largest_difference(result: SectionUncertainty, reference: SectionUncertainty) -> float:
    """Largest |difference| of the MC estimates and standard uncertainties, relative to each parameter's magnitude."""
    worst = 0.0
    for a, b in zip(result.monte_carlo.outputs, reference.monte_carlo.outputs):
        scale = max(abs(b.estimate), b.standard_uncertainty)
        worst = max(
            worst, abs(a.estimate - b.estimate) / scale, abs(a.standard_uncertainty - b.standard_uncertainty) / scale
        )
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1_000_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--naive", type=int, default=100, help="trials of the per-trial full-algorithm baseline")
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--method", choices=("denoised", "perturbed"), default="denoised")
    installed = [name for name in SECTION_BACKENDS if name in available_backends()]
    parser.add_argument("--backends", nargs="+", choices=SECTION_BACKENDS, default=installed)
    args = parser.parse_args()

    curve = NominalCurve(read_rotor37_section(ROTOR37, 2, scale=7.14))
    cloud = simulate_section_scan(
        curve, 1836, offset=(-0.1013e-3, 0.0538e-3), twist=math.radians(0.0512), form_amplitude=5e-6
    )
    instrument = load_instrument(INSTRUMENT)

    start = time.perf_counter()
    full_section_trials(cloud, curve, seed=args.seed, trials=args.naive, instrument=instrument, method=args.method)
    naive = (time.perf_counter() - start) / args.naive

    start = time.perf_counter()
    prepared = prepare_trials(cloud, curve, instrument=instrument, method=args.method)
    prepare_s = time.perf_counter() - start
    rows = []
    for backend in args.backends:
        result, trials_s, trials_cpu, statements_s = run_backend(prepared, curve, instrument, backend, args)
        rows.append((resolve_section_backend(backend).describe(), result, trials_s, trials_cpu, statements_s))
    own, children = peak_mib()

    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"points 1836, trials {args.trials}, workers {args.workers}, seed {args.seed}, method {args.method}; "
        f"load average at the end {load}"
    )
    print(f"shared preparation (evaluation, denoising, residual check): {prepare_s:.1f} s")
    reference = rows[0]
    print(
        f"{'backend':22s} {'trials s':>9s} {'CPU s':>8s} {'us/trial':>9s} {'vs ' + reference[0].split()[0]:>9s} "
        f"{'statements s':>13s} {'total s':>8s} {'largest rel. diff':>18s}"
    )
    for name, result, trials_s, trials_cpu, statements_s in rows:
        # Pool workers' CPU time is not counted until they exit: shown with one worker only.
        cpu = f"{'-':>8s} {'-':>9s}"
        if args.workers == 1:
            cpu = f"{trials_cpu:8.1f} {trials_cpu / args.trials * 1e6:9.1f}"
        print(
            f"{name:22s} {trials_s:9.1f} {cpu} "
            f"{reference[2] / trials_s:8.2f}x {statements_s:13.1f} {prepare_s + trials_s + statements_s:8.1f} "
            f"{largest_difference(result, reference[1]):18.1e}"
        )
    result = rows[-1][1]
    print(f"naive per-trial full algorithm: {naive * 1e3:.1f} ms/trial -> {naive * args.trials / 3600:.1f} h")
    print(f"peak memory: main {own:.0f} MiB, largest worker {children:.0f} MiB")
    print(f"thickness candidates {result.candidate_counts}")
    print()
    header = (
        f"{'parameter':24s} {'measured':>12s} {'u MC':>10s} {'U95 MC':>10s} {'u GUM':>10s} GUM=MC(§8) paper (value, u)"
    )
    print(header)
    measured = result.parameters.as_array()
    for j, name in enumerate(PARAMETER_NAMES):
        out = result.monte_carlo.outputs[j]
        gum = result.gum.outputs[j]
        angle = name == "twist_angle"
        # Twist: value in degrees, uncertainties in millidegrees (the reference paper's u is 0.31 m°).
        value_scale, u_scale = (math.degrees(1.0), 1e3 * math.degrees(1.0)) if angle else (1e3, 1e6)
        paper = PAPER.get(name)
        paper_text = "" if paper is None else f"{paper[0]:g}, {paper[1]:g}"
        print(
            f"{name:24s} {measured[j] * value_scale:12.6f} {out.standard_uncertainty * u_scale:10.5f} "
            f"{out.expanded_uncertainty * u_scale:10.5f} {gum.standard_uncertainty * u_scale:10.5f} "
            f"{'agree' if result.validation[j].validated else 'differ':10s} {paper_text}"
        )
    print("units: value mm (twist °), u and U95 µm (twist m°); paper column likewise")
    print("GUM=MC(§8): JCGM 101 §8 validation of the GUM interval by the Monte Carlo one (not a verdict on the part)")
    if result.check is not None:
        print(f"this cloud: {result.check.describe()}")
    budget = result.gum.sensitivities[1] * 1e6
    u_c = float(np.sqrt((budget**2).sum()))
    print(
        "chord GUM budget [µm]: "
        + ", ".join(f"{name} {b:.3f}" for name, b in zip(result.sources, budget))
        + f"; u_c {u_c:.3f}, with the reference paper's u3 = 2.087: "
        + f"U95 = {1.96 * math.hypot(u_c, 2.087):.3f} (paper 4.686)"
    )


if __name__ == "__main__":
    main()
