"""Held-out check of ``validate --field-correction`` on the real UR10 series B and D.

For each series, training size and seed, runs ``robocal-uncertainty validate <series> --robot
ur10 --train-poses N --trials T --seed S`` twice, without and with ``--field-correction`` (the
same split, Monte Carlo and held-out noise), and prints per row, averaged over the seeds: the
held-out 3-D RMS without and with the correction, and for the statement without and with it the
fraction of held-out points inside the 95 % interval per axis, inside the 95 % JCGM 102 region,
and the normalised error RMS per axis. Each run's report stays in ``--work``
(``out_<series>_<N>_s<seed>_<plain|field>/validation.json``); ``--reuse`` reads reports already
there instead of running them again.

    python benchmarks/study_field_correction_validate.py --series D B --train 200 500 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.cli import main as cli

SERIES = {
    "D": ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv",
    "B": ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b" / "measurements_joint_configurations.csv",
}
CAMPAIGN = {"D": "ur10.mcap", "B": "b.mcap"}


def _report(work: Path, series: str, n_train: int, seed: int, mode: str, trials: int, reuse: bool) -> dict:
    out = work / f"out_{series}_{n_train}_s{seed}_{mode}"
    if not (reuse and (out / "validation.json").is_file()):
        campaign = work / CAMPAIGN[series]
        if not campaign.is_file():
            with contextlib.redirect_stdout(io.StringIO()):
                assert cli(["import-csv", str(SERIES[series]), "--out", str(campaign)]) == 0
        args = ["validate", str(campaign), "--robot", "ur10", "--train-poses", str(n_train), "--trials", str(trials)]
        args += ["--seed", str(seed), "--out", str(out), "--force"] + (
            ["--field-correction"] if mode == "field" else []
        )
        with contextlib.redirect_stdout(io.StringIO()):
            assert cli(args) == 0
    return dict(json.loads((out / "validation.json").read_text()))


def _axes(report: dict, key: str) -> np.ndarray:
    return np.array([a[key] for a in report["axes"]])


def row(plain: list[dict], field: list[dict]) -> str:
    """One table row (markdown) from the reports of the seeds, without and with the correction."""
    check = [r["extra_settings"]["field_correction"] for r in field]
    before = np.mean([c["uncorrected_rms_3d_m"] for c in check]) * 1e3
    after = np.mean([c["corrected_rms_3d_m"] for c in check]) * 1e3

    def stats(reports: list[dict]) -> tuple[str, str, str]:
        inside = np.mean([_axes(r, "inside_fraction") for r in reports], axis=0) * 100
        region = np.mean([r["region_inside_fraction"] for r in reports]) * 100
        nrms = np.mean([_axes(r, "normalized_error_rms") for r in reports], axis=0)
        return " / ".join(f"{v:.1f}" for v in inside), f"{region:.1f}", " / ".join(f"{v:.2f}" for v in nrms)

    p, f = stats(plain), stats(field)
    return (
        f"{before:.3f} mm | {after:.3f} mm ({(after / before - 1) * 100:+.1f} %) | {p[0]} | {f[0]} | {p[1]} | {f[1]} "
        f"| {p[2]} | {f[2]} |"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--series", nargs="+", default=["D", "B"], choices=["B", "D"])
    ap.add_argument("--train", nargs="+", type=int, default=[200, 500])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--work", type=Path, help="folder of the campaigns and reports (default: a temporary one)")
    ap.add_argument("--reuse", action="store_true", help="read the reports already in --work")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        print(
            "| series | training poses | held-out 3-D RMS | with the correction | inside 95 % x / y / z | corrected "
            "| region 95 % | corrected | normalised RMS x / y / z | corrected |"
        )
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for series in args.series:
            if not SERIES[series].is_file():
                print(f"series {series}: {SERIES[series]} not found, skipped")
                continue
            for n_train in args.train:
                reports = {
                    mode: [_report(work, series, n_train, s, mode, args.trials, args.reuse) for s in args.seeds]
                    for mode in ("plain", "field")
                }
                print(f"| {series} | {n_train} | " + row(reports["plain"], reports["field"]), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
