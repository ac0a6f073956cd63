"""Simulated CMM clouds for the per-cloud coverage studies of the README (``section CLOUD --coverage-study N``).

Each cloud is a scan of a shipped nominal with the reference paper's offsets (-0.1013, 0.0538) mm and twist
0.0512°, a 5 µm three-wave form error and one draw of the instrument's errors (seeded), written
as ``x y z i j k`` in mm:

- ``cascade_800.txt``: the DFVLR L030-4 cascade blade at a 100 mm chord, 800 points, the reference paper's CMM;
- ``rotor37_400.txt`` and ``rotor37_5000.txt``: Rotor 37 at the reference paper's size, 400 and 5 000 points;
- ``rotor37_1836_cmm09.txt`` and ``rotor37_400_cmm09.txt``: Rotor 37, 1 836 and 400 points,
  measured with ``config/instruments/cmm_0.9_400.yaml`` (MPE (0.9 + L/400) µm).

Run: ``python benchmarks/section_study_clouds.py [--out section_clouds] [--seed 1]``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from robocal_uncertainty.app.section_inspection import load_section_nominal, resolve_instrument
from robocal_uncertainty.core.instruments.cmm import point_displacements
from robocal_uncertainty.inspection.section import evaluate_section
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.simulate import simulate_section_scan

CLOUDS = {
    "cascade_800.txt": ("cascade", 800, "cmm_reference_paper"),
    "rotor37_400.txt": ("rotor37", 400, "cmm_reference_paper"),
    "rotor37_5000.txt": ("rotor37", 5000, "cmm_reference_paper"),
    "rotor37_1836_cmm09.txt": ("rotor37", 1836, "config/instruments/cmm_0.9_400.yaml"),
    "rotor37_400_cmm09.txt": ("rotor37", 400, "config/instruments/cmm_0.9_400.yaml"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="section_clouds")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for k, (name, (nominal, n_points, instrument)) in enumerate(CLOUDS.items()):
        curve = load_section_nominal(nominal)
        true = simulate_section_scan(
            curve, n_points, offset=(-0.1013e-3, 0.0538e-3), twist=math.radians(0.0512), form_amplitude=5e-6
        )
        clean = evaluate_section(true, curve)
        sources = section_sources(clean, resolve_instrument(instrument)[0], probe_vectors=true.probe_vectors)
        rng = np.random.default_rng(np.random.SeedSequence(args.seed, spawn_key=(k,)))
        shift = point_displacements(sources, rng)[0][np.argsort(clean.order)]
        points = true.points.copy()
        points[:, :2] += shift
        assert true.probe_vectors is not None
        rows = np.column_stack([points * 1e3, true.probe_vectors])
        np.savetxt(out / name, rows, fmt="%.9f", header=f"unit: mm\n{nominal}, {n_points} points\nx y z i j k")
        print(f"{out / name}: {nominal}, {n_points} points, instrument {instrument}")


if __name__ == "__main__":
    main()
