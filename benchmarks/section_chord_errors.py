"""The chord error of a per-cloud study's noise draws, without the method: is it what the Monte Carlo assumes?

For scans 0 .. N-1 of a family of a cloud's study (``section CLOUD --coverage-study``, seed 23),
this rebuilds each simulated part and its noise draw exactly as
:func:`~robocal_uncertainty.inspection.coverage_study.study_scan` does, and prints the chord
error f(noisy scan) - f(noise-free scan) over the scans: mean, standard deviation, and how many
fall beyond ``--half-width`` (the half-width of the chord's 95 % interval in the study, about
1.96 standard deviations of the Monte Carlo's chord error). The same with an independent noise
stream is printed beside it. If the study's draws hold about 5 % beyond the half-width, a low
chord coverage in the first scans of a study is chance in those scans, not the method.

Run: ``python benchmarks/section_study_clouds.py --out clouds`` then
``python benchmarks/section_chord_errors.py clouds/rotor37_400.txt --nominal rotor37 --scans 200 --half-width 4.33``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from robocal_uncertainty.app.section_inspection import load_section_nominal, resolve_instrument
from robocal_uncertainty.core.instruments.cmm import point_displacements
from robocal_uncertainty.inspection import coverage_study as cs
from robocal_uncertainty.inspection.point_cloud import PointCloud, read_point_cloud
from robocal_uncertainty.inspection.section import PARAMETER_NAMES, evaluate_section
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.simulate import simulate_section_scan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cloud", type=Path)
    parser.add_argument("--nominal", default="rotor37")
    parser.add_argument("--instrument", default="cmm_reference_paper")
    parser.add_argument("--family", default="smooth", choices=cs.FAMILIES)
    parser.add_argument("--scans", type=int, default=200)
    parser.add_argument("--half-width", type=float, default=4.33, help="µm")
    args = parser.parse_args()
    curve = load_section_nominal(args.nominal)
    scene = cs.scenario_from_cloud(read_point_cloud(args.cloud), curve, resolve_instrument(args.instrument)[0])
    j = PARAMETER_NAMES.index("chord_length")
    family = cs.FAMILIES.index(args.family)
    errors: dict[str, list[float]] = {"study's noise draws": [], "independent draws": []}
    for index in range(args.scans):
        part_seq, noise_seq, _ = np.random.SeedSequence(23, spawn_key=(family, index)).spawn(3)
        part = cs.draw_part(args.family, np.random.default_rng(part_seq), scene)
        true_scan = simulate_section_scan(
            curve,
            scene.n_points,
            offset=scene.offset,
            twist=scene.twist,
            form_amplitude=part.form_amplitude,
            form_waves=part.form_waves,
            form_phase=part.form_phase,
            deviation=(lambda u, p=part: cs.feature_deviation(u, p.features, curve.period)) if part.features else None,
            parameters=scene.parameters,
        )
        if scene.probe_vectors is not None:
            true_scan = PointCloud(true_scan.points, scene.probe_vectors, true_scan.source)
        clean = evaluate_section(true_scan, curve)
        truth = clean.parameters.as_array()[j]
        sources = section_sources(clean, scene.instrument, probe_vectors=true_scan.probe_vectors)
        independent = np.random.SeedSequence(99, spawn_key=(family, index))
        for key, seq in zip(errors, (noise_seq, independent)):
            noisy = clean.points + point_displacements(sources, np.random.default_rng(seq))[0]
            errors[key].append((evaluate_section(noisy, curve).parameters.as_array()[j] - truth) * 1e6)
    for key, values in errors.items():
        e = np.asarray(values)
        beyond = int((np.abs(e) > args.half_width).sum())
        print(
            f"{key}: {e.size} scans, chord error mean {e.mean():+.2f} µm, sd {e.std(ddof=1):.2f} µm, "
            f"beyond ±{args.half_width} µm: {beyond} ({beyond / e.size:.1%}); in the first 58: "
            f"{int((np.abs(e[:58]) > args.half_width).sum())}"
        )


if __name__ == "__main__":
    main()
