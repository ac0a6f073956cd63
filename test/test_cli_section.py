"""``robocal-uncertainty section``: a small cloud end to end (file and PointCloud2 bag), the
report equals the API for the same seed, and every bad input ends in one line."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from robocal_uncertainty.app.section_inspection import inspect_section, load_section_nominal
from robocal_uncertainty.bagio.point_cloud2 import encode_point_cloud2, write_point_cloud2_mcap
from robocal_uncertainty.cli import main
from robocal_uncertainty.inspection.point_cloud import PointCloud, read_point_cloud
from robocal_uncertainty.inspection.section import evaluate_section
from robocal_uncertainty.inspection.simulate import simulate_section_scan

TRIALS = "3000"


@pytest.fixture(scope="module")
def scan() -> PointCloud:
    curve = load_section_nominal("rotor37")
    return simulate_section_scan(curve, 400, offset=(-0.1e-3, 0.05e-3), twist=math.radians(0.05), form_amplitude=5e-6)


@pytest.fixture(scope="module")
def cloud_file(scan: PointCloud, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("section") / "scan.txt"
    assert scan.probe_vectors is not None
    rows = np.column_stack([scan.points * 1e3, scan.probe_vectors])
    np.savetxt(path, rows, fmt="%.9f", header="unit: mm\nx y z i j k")
    return path


def test_section_report_equals_api(cloud_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    argv = ["section", str(cloud_file), "--nominal", "rotor37", "--trials", TRIALS, "--seed", "4", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "400 points" in text and "maximum thickness" in text and "profile, suction side" in text
    assert "interval (denoised MC)" in text and "GUM=MC(§8)" in text
    # 400 points: outside the coverage studies' scope (1 836-point scans), so nothing is verified.
    assert "note: This cloud: residual check passed" in text and "NOT verified for this cloud" in text
    assert sorted(p.name for p in out.iterdir()) == [
        "section.csv",
        "section.html",
        "section.json",
        "section.md",
        "section_histograms.png",
    ]
    data = json.loads((out / "section.json").read_text())
    assert "outside the scope of the coverage studies below (400 points, the studies 1836;" in data["coverage_note"]
    api = inspect_section(cloud_file, "rotor37", trials=int(TRIALS), seed=4)
    assert data["units"] == {"length": "m", "angle": "rad"}
    assert data["n_trials"] == 3000 and data["seed"] == 4
    # --backend auto (the default): numba where installed, recorded with its version.
    from robocal_uncertainty.kernels.section_kernels import resolve_section_backend

    chosen = resolve_section_backend("auto")
    assert data["backend"] == {"name": chosen.name, "version": chosen.version, "requested": "auto"}
    assert f"backend {chosen.describe()}" in text
    for row, mc in zip(data["parameters"], api.result.monte_carlo.outputs):
        assert row["u"] == pytest.approx(mc.standard_uncertainty, rel=1e-12)
        assert row["symmetric_interval"] == pytest.approx(
            [mc.probabilistically_symmetric.low, mc.probabilistically_symmetric.high], rel=1e-12
        )
    # The same command again refuses the non-empty report directory, then replaces it with --force.
    assert main(argv) == 1
    assert "exists and is not empty (give --force" in capsys.readouterr().err
    assert main([*argv, "--force", "--no-progress"]) == 0


def test_perturbed_method_is_flagged(cloud_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    argv = ["section", str(cloud_file), "--nominal", "rotor37", "--trials", "2000", "--out", str(out)]
    assert main([*argv, "--method", "perturbed", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "bias-corrected interval" in text and "note: This cloud: residual check passed" in text
    assert "NOT verified for this cloud" in text
    data = json.loads((out / "section.json").read_text())
    assert data["method"] == "perturbed"
    # Nothing verified: a 400-point cloud is outside the studies' scope (at 1 836 points the
    # offsets and twist would be, the max/min parameters' reflected intervals under-cover).
    assert not any(row["coverage_verified"] for row in data["parameters"])
    assert data["coverage_study_scope"]["outside_because"] == "400 points, the studies 1836"


def test_section_from_a_point_cloud2_bag(scan: PointCloud, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_point_cloud2_mcap(
        tmp_path / "scan.mcap", [encode_point_cloud2(1, "blade", scan.points, scan.probe_vectors, float64=True)]
    )
    out = tmp_path / "report"
    assert main(["section", str(bag), "--nominal", "rotor37", "--trials", "2000", "--out", str(out)]) == 0
    assert "frame blade" in capsys.readouterr().out
    data = json.loads((out / "section.json").read_text())
    assert data["frame_id"] == "blade" and data["n_points"] == 400


def test_a_cloud_the_check_flags_is_not_verified(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A 1 836-point scan with an 8 µm dent 3 mm wide on the pressure side (narrower than the
    # narrowest smoothing window) and one draw of the seed's CMM errors.
    from robocal_uncertainty.core.instruments.cmm import CmmInstrument, point_displacements
    from robocal_uncertainty.inspection.coverage_study import Feature, feature_deviation
    from robocal_uncertainty.inspection.section_mc import section_sources

    curve = load_section_nominal("rotor37")
    dent = (Feature("dent", 0.2, 8e-6, 3e-3),)
    true = simulate_section_scan(
        curve, 1836, form_amplitude=5e-6, deviation=lambda u: feature_deviation(u, dent, curve.period)
    )
    clean = evaluate_section(true, curve)
    sources = section_sources(clean, CmmInstrument(), probe_vectors=true.probe_vectors)
    noisy = clean.points + point_displacements(sources, np.random.default_rng(7))[0]
    path = tmp_path / "dented.txt"
    np.savetxt(path, np.column_stack([noisy, np.zeros(len(noisy))]) * 1e3, fmt="%.9f", header="unit: mm\nx y z")
    out = tmp_path / "report"
    assert (
        main(["section", str(path), "--nominal", "rotor37", "--trials", "2000", "--out", str(out), "--no-progress"])
        == 0
    )
    text = capsys.readouterr().out
    assert "residual check FLAGGED this cloud" in text and "NOT verified for this cloud" in text
    assert "verified" not in text.replace("not verified for this cloud", "").replace("NOT verified for this cloud", "")
    data = json.loads((out / "section.json").read_text())
    assert data["residual_check"]["flagged"] is True
    assert not any(row["coverage_verified"] for row in data["parameters"])


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ([], "section needs --nominal"),
        (["--nominal", "rotor37:14"], r"needs a surface K in 1\.\.13"),
        (["--nominal", "nowhere.txt"], "is neither a file nor a shipped blade"),
        (["--nominal", "rotor37", "--instrument", "nope.yaml"], "is neither a file nor a shipped instrument"),
        (["--nominal", "rotor37", "--trials", "0"], "--trials must be a positive integer"),
        (["--nominal", "rotor37", "--workers", "0"], "--workers must be a positive integer"),
        (["--nominal", "rotor37", "--seed", "-1"], "--seed must be an integer >= 0"),
        (["--nominal", "rotor37", "--topic", "/points"], "apply to bags only"),
        (["--nominal", "rotor37", "--demo"], "CLOUD file or bag, or --demo"),
    ],
)
def test_bad_options_end_in_one_line(
    cloud_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], match: str
) -> None:
    status = main(["section", str(cloud_file), "--trials", "10", "--out", str(tmp_path / "r"), *extra])
    err = capsys.readouterr().err.strip()
    assert status == 1, err
    assert len(err.splitlines()) == 1
    assert err.startswith("robocal-uncertainty section: error:")
    assert match in err or __import__("re").search(match, err), err


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("", "no data rows|empty|no point"),
        ("1 2 3\n4 5 6\n", "unit"),
        ("# unit: mm\n1 2 3\nnan 5 6\n", "NaN|finite|nan"),
        ("# unit: mm\n1 2 3\n4 5 6\n7 8 9\n", "at least|too few|points"),
    ],
)
def test_bad_clouds_end_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, match: str
) -> None:
    path = tmp_path / "bad.txt"
    path.write_text(content)
    status = main(["section", str(path), "--nominal", "rotor37", "--trials", "10", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert status == 1, err
    assert len(err.splitlines()) == 1
    assert __import__("re").search(match, err, flags=2), err


def test_other_section_than_the_nominal_is_refused(
    scan: PointCloud, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "other.txt"
    other = simulate_section_scan(load_section_nominal("cascade"), 300)
    np.savetxt(path, other.points * 1e3, header="unit: mm")
    status = main(["section", str(path), "--nominal", "rotor37", "--trials", "10", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert status == 1 and len(err.splitlines()) == 1, err


def _write_scan(path: Path, cloud: PointCloud, noise: NDArray[np.float64] | None = None) -> Path:
    points = cloud.points.copy()
    if noise is not None:
        points[:, :2] += noise
    assert cloud.probe_vectors is not None
    np.savetxt(path, np.column_stack([points * 1e3, cloud.probe_vectors]), fmt="%.9f", header="unit: mm\nx y z i j k")
    return path


@pytest.fixture(scope="module")
def repeat_files(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """CLOUD and 3 repeated scans of the demo section (each with its own 1 um probing noise)."""
    curve = load_section_nominal("rotor37")
    folder = tmp_path_factory.mktemp("repeats")
    rng = np.random.default_rng(7)
    files = []
    for k in range(4):
        scan = simulate_section_scan(
            curve, 400, offset=(-0.1e-3, 0.05e-3), twist=math.radians(0.05), form_amplitude=5e-6
        )
        files.append(_write_scan(folder / f"scan{k}.txt", scan, rng.normal(0.0, 1e-6, (scan.n_points, 2))))
    return files


def test_repeat_scans_give_the_seeds_chord_budget(
    repeat_files: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report"
    cloud, *repeats = repeat_files
    argv = ["section", str(cloud), "--nominal", "rotor37", "--trials", "2000", "--out", str(out), "--no-progress"]
    assert main([*argv, "--repeat-scans", *map(str, repeats)]) == 0
    text = capsys.readouterr().out
    # u3 computed independently: the standard deviation (ddof 1) of the repeated scans' chords.
    curve = load_section_nominal("rotor37")
    chords = [evaluate_section(read_point_cloud(f), curve).parameters.chord_length for f in repeats]
    u3 = float(np.std(chords, ddof=1))
    assert u3 > 0
    data = json.loads((out / "section.json").read_text())
    assert data["repeat_scans"] == [str(f) for f in repeats]
    budget = data["gum_with_repeatability"]
    assert budget["n_scans"] == 3 and budget["repeatability_dof"] == 2
    chord = budget["parameters"][1]
    assert chord["name"] == "chord_length" and chord["unit"] == "m"
    assert chord["contributions"]["repeatability"] == pytest.approx(u3, rel=1e-6)
    terms = np.array(list(chord["contributions"].values()))
    assert chord["U"] == pytest.approx(chord["k"] * math.sqrt(float((terms**2).sum())), rel=1e-9)
    # The printed budget: u1 MPE, u2 thermal, u3 repeatability, the other sources, u_c, k, U95 (um).
    block = text[text.index("GUM budget of the chord length with repeatability") :].splitlines()
    assert "3 repeated scans" in block[0] and "in µm" in block[0]
    assert [line.split()[:2] for line in block[1:4]] == [["u1", "MPE"], ["u2", "thermal"], ["u3", "repeatability"]]
    assert [line.split()[0] for line in block[4:9]] == ["probing", "algorithm", "u_c", "k", "U95"]
    assert float(block[3].split()[2]) == pytest.approx(u3 * 1e6, abs=6e-5)
    contributions = [float(line.split()[-2]) for line in block[1:6]]
    assert all(line.split()[-1] == "µm" for line in block[1:6])
    u_c, k, u95 = float(block[6].split()[1]), float(block[7].split()[1]), float(block[8].split()[1])
    assert block[8].split()[2] == "µm"
    assert u_c == pytest.approx(math.sqrt(sum(c * c for c in contributions)), abs=2e-4)
    assert u95 == pytest.approx(k * math.sqrt(sum(c * c for c in contributions)), abs=1e-3)
    markdown = (out / "section.md").read_text()
    assert "## GUM budget with repeatability (reference paper's table)" in markdown
    assert f"| u3 repeatability | {u3 * 1e6:.4f} µm |" in markdown


@pytest.mark.parametrize(
    ("case", "match"),
    [
        ("one", "--repeat-scans needs at least 2 repeated scans"),
        ("demo", "--demo simulates no repeats"),
        ("other", "repeated scan .*other.txt: measured points do not match the nominal section"),
    ],
)
def test_bad_repeat_scans_end_in_one_line(
    repeat_files: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, match: str
) -> None:
    cloud, first, second, _ = repeat_files
    other = _write_scan(tmp_path / "other.txt", simulate_section_scan(load_section_nominal("rotor37:5"), 400))
    argv = {
        "one": ["section", str(cloud), "--nominal", "rotor37", "--repeat-scans", str(first)],
        "demo": ["section", "--demo", "--repeat-scans", str(first), str(second)],
        "other": ["section", str(cloud), "--nominal", "rotor37", "--repeat-scans", str(first), str(other)],
    }[case]
    status = main([*argv, "--trials", "10", "--out", str(tmp_path / "r"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert status == 1, err
    assert len(err.splitlines()) == 1
    assert err.startswith("robocal-uncertainty section: error:")
    assert __import__("re").search(match, err), err


def test_a_backend_without_a_section_kernel_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["section", "--demo", "--backend", "cupy", "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (
        "robocal-uncertainty section: error: backend 'cupy' has no blade-section kernel: use numba or numpy "
        "(auto picks numba where installed)"
    )
    assert not (tmp_path / "r").exists()


def test_coverage_study_of_the_cloud(cloud_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--coverage-study N: the cloud's own study (its 400 points, its probe vectors, the seed's CMM);
    one scan per family verifies nothing, and the report says so and records the study."""
    out = tmp_path / "report"
    argv = ["section", str(cloud_file), "--nominal", "rotor37", "--trials", "2000", "--out", str(out)]
    assert main([*argv, "--coverage-study", "1", "--study-trials", "300", "--study-seed", "5", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "4 simulated scans" in text and "expected" in text
    assert text.count("NOT VERIFIED for this part (own study)") == 9
    assert "NOT verified for this part, layout and instrument (families with fewer than 53" in text
    assert "% verified for this part" not in text
    data = json.loads((out / "section.json").read_text())
    own = data["coverage_study_this_cloud"]
    assert own["study_seed"] == 5 and own["scans_per_family"] == 1 and own["points"] == 400
    assert own["families"] == ["smooth", "side", "edge", "erosion"] and own["elapsed_s"] > 0
    assert own["probe_vectors_from_cloud"] is True and own["instrument"]["mpe_k"] == 350
    assert all(c["scans"] == 1 for c in own["counts"].values()) and not own["verified_all"]
    assert not any(row["coverage_verified"] for row in data["parameters"])
    assert "## Coverage study of this cloud" in (out / "section.md").read_text()
    # The scans' Monte Carlo ran on --backend auto, recorded and printed.
    from robocal_uncertainty.kernels.section_kernels import resolve_section_backend

    kernels = resolve_section_backend("auto").describe()
    assert own["trial_backend"] == kernels and f"trial kernels {kernels}" in text
    assert f"trial kernels {kernels}" in (out / "section.md").read_text()
    # Without a study the same cloud is outside the stored studies' scope: not verified.
    assert main([*argv, "--force", "--no-progress"]) == 0
    assert "NOT verified for this cloud" in capsys.readouterr().out
    # The study runs method denoised only.
    assert main([*argv, "--force", "--method", "perturbed", "--coverage-study", "1"]) == 1
    assert "give --method denoised" in capsys.readouterr().err


def test_a_study_that_verifies_says_so(cloud_file: Path) -> None:
    """The verdict of a study whose every cell passes the rule, rendered for a cloud the check passed."""
    from robocal_uncertainty.app.section_inspection import inspect_section
    from robocal_uncertainty.core.instruments.cmm import CmmInstrument
    from robocal_uncertainty.inspection.coverage_rule import family_cells
    from robocal_uncertainty.inspection.coverage_study import ScenarioStudy
    from robocal_uncertainty.inspection.section import PARAMETER_NAMES
    from robocal_uncertainty.report.section_report import coverage_summary, format_section_table

    run = inspect_section(cloud_file, "rotor37", trials=2000, seed=1)
    assert run.result.check is not None and not run.result.check.flagged
    counts = dict.fromkeys(("smooth", "side", "edge", "erosion"), (80, 10, (68,) * 9, (77,) * 9))  # 97.1 %
    study = ScenarioStudy(
        "test", 400, 0.81, CmmInstrument(), 1.0, 3e-6, True, 23, 80, 2000, ("smooth", "side", "edge", "erosion"),
        1.0, 1, counts, family_cells(counts, PARAMETER_NAMES),
    )  # fmt: skip
    assert study.verified_all
    table = format_section_table(run.result, run.corrections, study=study)
    assert table.count("97.1% verified for this part, layout and instrument") == 9
    assert "Every stated interval is verified for this part, layout and instrument" in coverage_summary(
        run.result, study
    )
    # One family at 60 of 70 (85.7 %) fails the floor: that parameter is not verified.
    worse = dict(counts, edge=(80, 10, (60, *(68,) * 8), (70, *(77,) * 8)))
    failing = dataclasses.replace(study, counts=worse, cells=family_cells(worse, PARAMETER_NAMES))
    table = format_section_table(run.result, run.corrections, study=failing)
    assert "85.7% NOT VERIFIED for this part (own study)" in table and table.count("verified for this part") == 8


def test_shipped_nominal_beside_a_directory_of_its_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`--out cascade --nominal cascade`: the report directory is claimed before the work, and a
    directory named like a shipped blade is not a nominal file."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cascade").mkdir()
    (tmp_path / "rotor37").mkdir()
    assert load_section_nominal("cascade").period == pytest.approx(0.2017, abs=1e-4)
    assert load_section_nominal("rotor37").period == pytest.approx(0.80977, abs=1e-4)
