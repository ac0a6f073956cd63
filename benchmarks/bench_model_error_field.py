"""What the model-error field costs: its estimate, its draws, and ``evaluate`` with and without it.

Times, in one run on one machine, (1) ``estimate_field`` of the UR10 series D (points, 632
poses) and of a 53-pose subset, (2) 20 000 of the field's draws (``FieldNormal.sample``, 632
calibration poses and one test configuration), and (3) the wall time of the README's
``evaluate`` of series D (20 000 trials by default; numba backend) with the model-error field
(the default) and with the independent model (``--independent-model-error``; in a checkout from
before the switch, the default and ``--model-error-field``); as ratios: the field's ``evaluate``
over the independent model's, and,
with ``--baseline PATH`` (another checkout of the package, e.g. main's), each time of this
checkout over that checkout's, measured alternately in the same run. Every number is printed with
the machine's load average (2 shared cores: compare ratios, not seconds).

    python benchmarks/bench_model_error_field.py --baseline /work/main [--trials 20000 100000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SERIES_D = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
TEST_JOINTS = ["0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]

_PIECES = r"""
import sys, time
import numpy as np
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty import UncertaintySettings
from robocal_uncertainty.uncertainty.calibration.preparation import _tracker_distances
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy, pose_noise_covariances
from robocal_uncertainty.uncertainty import model_error_draws as med

model = load_robot_model(resolve_robot_config("ur10"))
settings = UncertaintySettings()
full = read_tracker_csv(sys.argv[1])
for label, campaign in (("632", full), ("53", full.subset(np.arange(0, 632, 12)))):
    cal = identify(model, campaign)
    q = campaign.joint_positions
    dist = _tracker_distances(settings, campaign)
    noise = pose_noise_covariances(cal, q, settings.tracker_noise, settings.encoder_noise, dist)
    shape = assess_model_adequacy(cal, q, settings.tracker_noise, settings.encoder_noise, dist).residual_covariance
    t0 = time.perf_counter()
    est = med.estimate_field(cal, q, noise, shape)
    print(f"estimate_{label} {time.perf_counter() - t0:.4f}")
    if label == "632":
        qc = np.array([[float(v) for v in sys.argv[2:8]]])
        draw = med.FieldNormal(q, qc, est, innovations=med.standardised_innovations(np.asarray(cal.residuals)))
        t0 = time.perf_counter()
        for i in range(4):
            draw.sample(np.random.default_rng(i), 5000)
        print(f"draws_20000 {time.perf_counter() - t0:.4f}")
"""


_CACHE = tempfile.mkdtemp(prefix="bench_field_numba_")


def _env(code: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(code)
    if code != ROOT:
        # Leave the baseline checkout as it is: no bytecode, the compiled kernels cached elsewhere.
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        env["NUMBA_CACHE_DIR"] = _CACHE
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env.setdefault(name, "1")
    return env


def _pieces(code: Path, work: Path) -> dict[str, float]:
    # Run from `work`: `python -c` puts the working directory first on the path, before PYTHONPATH.
    out = subprocess.run(
        [sys.executable, "-c", _PIECES, str(SERIES_D), *TEST_JOINTS],
        env=_env(code),
        capture_output=True,
        text=True,
        check=True,
        cwd=work,
    ).stdout
    return {k: float(v) for k, v in (line.split() for line in out.splitlines() if line.strip())}


def _evaluate(code: Path, mcap: Path, trials: int, field: bool, work: Path) -> float:
    out = work / f"report_{time.monotonic_ns()}"
    cmd = [sys.executable, "-m", "robocal_uncertainty", "evaluate", str(mcap), "--robot", "ur10"]
    cmd += ["--trials", str(trials), "--backend", "numba", "--out", str(out), "--test-joints", *TEST_JOINTS]
    # Since the field became the default, `--independent-model-error` gives the per-pose model;
    # a checkout from before has only `--model-error-field` (the field) and the independent default.
    source = code / "robocal_uncertainty" / "uncertainty" / "sources" / "model_error.py"
    if "--independent-model-error" in source.read_text():
        if not field:
            cmd.append("--independent-model-error")
    elif field:
        cmd.append("--model-error-field")
    t0 = time.perf_counter()
    subprocess.run(cmd, env=_env(code), capture_output=True, check=True, cwd=work)
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", type=Path, help="another checkout of the package to compare with (e.g. main's)")
    ap.add_argument(
        "--trials", type=int, nargs="*", default=[20_000], help="evaluate trial counts (none: only the pieces)"
    )
    ap.add_argument("--skip-pieces", action="store_true", help="time only evaluate")
    ap.add_argument("--repeats", type=int, default=3, help="runs of the pieces per checkout (the fastest is printed)")
    args = ap.parse_args()
    codes = {"this": ROOT}
    if args.baseline is not None:
        codes["baseline"] = args.baseline.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        mcap = work / "ur10.mcap"
        subprocess.run(
            [sys.executable, "-m", "robocal_uncertainty", "import-csv", str(SERIES_D), "--out", str(mcap)],
            env=_env(ROOT),
            capture_output=True,
            check=True,
        )
        # Compile (and cache) the numba kernels of each checkout before timing.
        for code in codes.values():
            _evaluate(code, mcap, 1000, False, work)
        print(f"load average at start: {os.getloadavg()[0]:.2f}")
        if not args.skip_pieces:
            # Each checkout's pieces in a fresh process, alternately, `--repeats` times: the fastest.
            pieces: dict[str, dict[str, float]] = {}
            for _ in range(args.repeats):
                for name, code in codes.items():
                    for key, value in _pieces(code, work).items():
                        pieces.setdefault(name, {})[key] = min(value, pieces.get(name, {}).get(key, float("inf")))
            for key in pieces["this"]:
                line = f"{key:<14} this {pieces['this'][key]:7.3f} s"
                if "baseline" in pieces:
                    b = pieces["baseline"][key]
                    line += f"   baseline {b:7.3f} s   this / baseline {pieces['this'][key] / b:.3f}"
                print(line, flush=True)
        for trials in args.trials:
            times = {}
            for name, code in codes.items():
                for field in (False, True):
                    times[name, field] = _evaluate(code, mcap, trials, field, work)
            load = os.getloadavg()[0]
            for name in codes:
                d, f = times[name, False], times[name, True]
                print(
                    f"evaluate {trials} trials, {name:<8}: independent {d:6.1f} s, field {f:6.1f} s, "
                    f"field / independent {f / d:.2f} (load average {load:.2f})",
                    flush=True,
                )
            if "baseline" in codes:
                print(
                    f"evaluate {trials} trials, field: this / baseline "
                    f"{times['this', True] / times['baseline', True]:.3f}; independent: this / baseline "
                    f"{times['this', False] / times['baseline', False]:.3f}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
