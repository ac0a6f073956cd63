"""Every trial-kernel backend gives the numpy backend's trials, from the same draws.

The backends walk the kinematic chain in a different order of floating-point operations
(fused per pose, compiled, or on an array module), so they agree to rounding, not bit for bit;
the bar is 1e-12 relative (see the block test for what relative means for a parameter near
zero). Checked here for every measurement type (points, 6-DOF
poses), model layout (modified DH with and without beta, a URDF with a base-link mount, a URDF
with a prismatic joint, a tool rotation), output frame and source set (the noise sources, the
subset and lambda sources with per-trial weights, the model-error source), on whole trial
blocks, several sub-batches long. The CuPy backend runs with numpy standing in for CuPy as its
array module (how CI checks it; ``benchmarks/bench_gpu.py`` measures it on a GPU).
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.core.urdf_model import load_urdf, robot_model_from_urdf
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.kernels import (
    CupyBackend,
    NumbaBackend,
    available_backends,
    backend_names,
    get_backend,
    register_backend,
    resolve_backend,
)
from robocal_uncertainty.kernels.predictors import ArrayModulePredictor, CompiledMeasurement, CompiledPredictor
from robocal_uncertainty.montecarlo.engine import run_trials
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty, prepare_calibration_trials

ROOT = Path(__file__).resolve().parents[2]
URDF_DIR = ROOT / "test" / "data" / "urdf"
HAS_NUMBA = NumbaBackend().available()
needs_numba = pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed (extra 'fast')")
RTOL = 1e-12


@pytest.fixture(autouse=True)
def _cupy_on_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ``cupy`` backend with numpy standing in for CuPy (restored after each test)."""
    from robocal_uncertainty.kernels import registry

    monkeypatch.setitem(registry._REGISTRY, "cupy", CupyBackend(module="numpy"))


BACKENDS = [pytest.param("numba", marks=needs_numba), "cupy"]


def _models() -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = [
        (name, load_robot_model(resolve_robot_config(name))) for name in ("ur10", "paper_arm")
    ]
    out += [(path.name, robot_model_from_urdf(load_urdf(path), None, None)) for path in sorted(URDF_DIR.glob("*.urdf"))]
    out += [(f"{name}+tool_rotation", model.with_tool_rotation()) for name, model in list(out)]  # type: ignore[attr-defined]
    return out


MODELS = _models()


def _predictor(backend: str, layout: object, p0: np.ndarray, q0: np.ndarray) -> object:
    if backend == "numba":
        return CompiledPredictor.at(layout, p0, q0)  # type: ignore[arg-type]
    return ArrayModulePredictor.on("numpy", layout, p0, q0)  # type: ignore[arg-type]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("name", "model"), MODELS, ids=[n for n, _ in MODELS])
def test_walk_equals_forward_kinematics(backend: str, name: str, model: object) -> None:
    """Points and poses at micro-perturbations (the series) and at 0.01 (the direct cos/sin),
    per-trial readings, shared readings and shared parameters, against ``predict``."""
    _ = name
    layout = model.layout  # type: ignore[attr-defined]
    rng = np.random.default_rng(11)
    p0 = model.parameter_vector() + rng.normal(0.0, 1e-3, layout.size)  # type: ignore[attr-defined]
    q0 = rng.uniform(-2.0, 2.0, (7, layout.n_joints))
    predictor = _predictor(backend, layout, p0, q0)
    for measurement, f in ((POINT, predictor), (PoseMeasurement((1e-5,) * 3, (1e-4,) * 3), predictor.poses)):  # type: ignore[attr-defined]
        for scale in (1e-6, 1e-2):
            p = p0 + rng.normal(0.0, scale, (5, layout.size))
            q = q0 + rng.normal(0.0, scale, (5, *q0.shape))
            for args in ((p, q), (p, q0), (p0, q), (p0, q0), (p[:, None, :], q)):
                want = measurement.predict(layout, *args)
                got = f(*args)  # type: ignore[operator]
                assert got.shape == want.shape
                np.testing.assert_allclose(got, want, rtol=0.0, atol=RTOL)  # values ~1 m and ~1


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_trial_does_not_depend_on_its_batch(backend: str) -> None:
    """Bit for bit: a trial's values are the same walked alone or with others (the chunking of
    the Monte Carlo can never change a result)."""
    model = load_robot_model(resolve_robot_config("paper_arm"))
    layout = model.layout
    rng = np.random.default_rng(2)
    p0 = model.parameter_vector()
    q0 = rng.uniform(-2.0, 2.0, (9, 6))
    p = p0 + rng.normal(0.0, 1e-6, (6, layout.size))
    q = q0 + rng.normal(0.0, 1e-6, (6, *q0.shape))
    q[3, 2, 1] += 0.5  # one trial's change too large for the series
    predictor = _predictor(backend, layout, p0, q0)
    whole = predictor.poses(p, q)  # type: ignore[attr-defined]
    for t in range(6):
        np.testing.assert_array_equal(predictor.poses(p[t : t + 1], q[t : t + 1]), whole[t : t + 1])  # type: ignore[attr-defined]


def _campaign_model(layout: str, six_dof: bool, frame: str) -> tuple[object, object]:
    if layout.endswith(".urdf"):
        model = robot_model_from_urdf(load_urdf(URDF_DIR / layout), None, None)
    else:
        model = load_robot_model(resolve_robot_config(layout))
    settings = SimulationSettings(n_poses=30, frame=frame, orientation_std=1e-4 if six_dof else None)  # type: ignore[arg-type]
    return model, simulate_campaign(model, settings, seed=5).campaign


CASES = [
    # layout, 6-DOF, campaign frame, output frame, sources
    ("paper_arm", False, "tracker", "measurement", ("tracker", "encoder")),
    ("paper_arm", False, "base", "base", ("tracker", "encoder", "lambda", "n_poses", "pose_choice")),
    ("ur10", False, "tracker", "base", ("tracker", "encoder", "residual")),
    ("paper_arm", True, "tracker", "measurement", ("tracker", "encoder", "residual", "tracker_orientation")),
    ("ur10.urdf", False, "tracker", "measurement", ("tracker", "encoder", "residual", "pose_choice")),
    ("ur10.urdf", True, "base", "measurement", ("tracker", "encoder", "tracker_orientation", "lambda")),
    ("rail_arm.urdf", False, "tracker", "measurement", ("tracker", "encoder", "residual", "n_poses")),
    ("rail_arm.urdf", True, "tracker", "base", ("tracker", "encoder", "tracker_orientation")),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("layout", "six_dof", "frame", "output", "sources"), CASES)
def test_trial_blocks_equal_the_numpy_backend(
    backend: str,
    layout: str,
    six_dof: bool,
    frame: str,
    output: str,
    sources: tuple[str, ...],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Whole trial blocks (positions and orientations at the test configurations, parameters)
    from the same draws, 600 trials (three sub-batches, the last one short). With numba the
    whole re-identification of every sub-batch runs in the compiled kernel (checked: it never
    hands a sub-batch back to the numpy iteration here)."""
    compiled: list[bool] = []
    solve_chord = CompiledMeasurement.solve_chord

    def recording(self: CompiledMeasurement, *args: object, **kwargs: object) -> object:
        solved = solve_chord(self, *args, **kwargs)  # type: ignore[arg-type]
        compiled.append(solved is not None)
        return solved

    monkeypatch.setattr(CompiledMeasurement, "solve_chord", recording)
    model, campaign = _campaign_model(layout, six_dof, frame)
    calibration = identify(model, campaign)  # type: ignore[arg-type]
    rng = np.random.default_rng(1)
    test_joints = campaign.joint_positions[:3] + rng.normal(0.0, 0.3, (3, model.n_joints))  # type: ignore[attr-defined]
    settings = UncertaintySettings(sources=sources)
    blocks = {}
    for name in ("numpy", backend):
        trials = prepare_calibration_trials(
            model,  # type: ignore[arg-type]
            campaign,  # type: ignore[arg-type]
            test_joints,
            settings=settings,
            calibration=calibration,
            frame=output,
            backend=name,
        )
        blocks[name] = run_trials(trials, seed=3, n_trials=600, block_size=600).samples
    if backend == "numba":
        assert compiled == [True, True, True]
    want, got = blocks["numpy"], blocks[backend]
    assert np.isfinite(want).all()
    diff = np.abs(got - want).max(axis=0)
    n_pos = 3 * test_joints.shape[0]
    # Positions: 1e-12 of their value. Parameters: 1e-12 of their value, or of 1 m or 1 rad
    # for those near zero (a joint's beta, a theta offset: a rounding of the chain, 1e-16 m,
    # moves them by ~1e-15, which is 1e-12 of a value of 1e-3), and 1e-10 of their spread.
    scale = np.abs(want).max(axis=0)
    scale[n_pos:] = np.maximum(scale[n_pos:], 1.0)
    assert (diff <= RTOL * scale).all(), (diff / scale).max()
    spread = want.std(axis=0)
    assert (diff <= 1e-10 * spread).all(), (diff / spread).max()
    # The trials differ from each other far beyond that: the check can fail.
    assert (spread[:n_pos] > 1e3 * RTOL * scale[:n_pos]).all()


@needs_numba
def test_numba_results_do_not_depend_on_chunking_and_survive_pickling() -> None:
    model, campaign = _campaign_model("paper_arm", False, "tracker")
    calibration = identify(model, campaign)  # type: ignore[arg-type]
    trials = prepare_calibration_trials(
        model,  # type: ignore[arg-type]
        campaign,  # type: ignore[arg-type]
        campaign.joint_positions[:2],  # type: ignore[attr-defined]
        settings=UncertaintySettings(sources=("tracker", "encoder", "pose_choice")),
        calibration=calibration,
        backend="numba",
    )
    one = run_trials(trials, seed=8, n_trials=900, block_size=300).samples
    chunked = run_trials(trials, seed=8, n_trials=900, block_size=300, chunk_blocks=3).samples
    np.testing.assert_array_equal(chunked, one)
    # What a worker process (or a Dask worker) gets: the pickled trial block.
    shipped = pickle.loads(pickle.dumps(trials))
    assert isinstance(shipped.solver.predictor, CompiledMeasurement)
    np.testing.assert_array_equal(run_trials(shipped, seed=8, n_trials=900, block_size=300).samples, one)


@needs_numba
@pytest.mark.parametrize(("name", "model"), MODELS, ids=[n for n, _ in MODELS])
def test_numba_test_configurations_walk_and_values(name: str, model: object) -> None:
    """The numba backend's tool at the test configurations: numpy's nearby-point walk for up to
    four configurations where that walk supports the layout, the compiled walk otherwise; either
    way, points and poses equal to ``predict`` to 1e-12 (values ~1 m and ~1)."""
    from robocal_uncertainty.core.kinematics import NearbyPoints
    from robocal_uncertainty.kernels.registry import NUMPY_WALK_UP_TO

    _ = name
    layout = model.layout  # type: ignore[attr-defined]
    rng = np.random.default_rng(23)
    p0 = model.parameter_vector() + rng.normal(0.0, 1e-3, layout.size)  # type: ignore[attr-defined]
    for n_test in (1, NUMPY_WALK_UP_TO, NUMPY_WALK_UP_TO + 1, 40):
        q0 = rng.uniform(-2.0, 2.0, (n_test, layout.n_joints))
        predictor = NumbaBackend().tool_predictor(layout, p0, q0)
        small = n_test <= NUMPY_WALK_UP_TO and NearbyPoints.supports(layout)
        assert isinstance(predictor, NearbyPoints if small else CompiledPredictor)
        for scale in (1e-6, 1e-2):  # the series, and the direct cosine and sine
            p = p0 + rng.normal(0.0, scale, (6, layout.size))
            q = q0 + rng.normal(0.0, scale, (6, *q0.shape))
            for measurement, f in ((POINT, predictor), (PoseMeasurement((1e-5,) * 3, (1e-4,) * 3), predictor.poses)):  # type: ignore[attr-defined]
                want = measurement.predict(layout, p, q)
                np.testing.assert_allclose(f(p, q), want, rtol=0.0, atol=RTOL)  # type: ignore[operator]


def test_registry_names_auto_and_errors() -> None:
    assert set(backend_names()) >= {"numpy", "numba", "cupy"}
    assert "numpy" in available_backends()
    assert get_backend("auto").name == ("numba" if HAS_NUMBA else "numpy")
    with pytest.raises(ConfigError, match="backend must be one of auto, numpy, numba, cupy, got 'fortran'"):
        get_backend("fortran")
    register_backend(CupyBackend(module="no_such_array_module"))  # the fixture restores it
    with pytest.raises(ConfigError, match=r"'cupy' is not available.*robocal_uncertainty\[gpu\]"):
        get_backend("cupy")
    info = resolve_backend("numpy")
    assert (info.name, info.version, info.requested) == ("numpy", np.__version__, "numpy")
    assert info.describe() == f"numpy {np.__version__}"


def test_backend_recorded_in_the_result_and_the_reports(tmp_path: Path) -> None:
    from robocal_uncertainty.report.json_report import uncertainty_to_dict

    model = load_robot_model(resolve_robot_config("paper_arm"))
    campaign = simulate_campaign(model, SimulationSettings(n_poses=30), seed=2).campaign
    result = evaluate_uncertainty(model, campaign, campaign.joint_positions[:1], trials=300, backend="cupy")
    assert result.backend is not None
    assert (result.backend.name, result.backend.requested) == ("cupy", "cupy")
    assert "numpy standing in" in result.backend.version
    data = json.loads(json.dumps(uncertainty_to_dict(result, robot_name="paper_arm")))
    assert data["monte_carlo"]["backend"] == {
        "name": "cupy",
        "version": result.backend.version,
        "requested": "cupy",
    }


def test_cli_backend_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """--backend picks the kernels and is recorded; one that is not there is a one-line error
    before any work."""
    from robocal_uncertainty.cli import main
    from robocal_uncertainty.kernels import registry

    campaign = tmp_path / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--out", str(campaign), "--seed", "3"]) == 0
    common = ["evaluate", str(campaign), "--robot", "paper_arm", "--trials", "400", "--no-budget", "--no-sweeps"]
    common += ["--no-progress", "--test-joints", "0.1", "-1.9", "-1.2", "-1.6", "-1.1", "0.4"]
    monkeypatch.setitem(registry._REGISTRY, "cupy", CupyBackend(module="no_such_array_module"))
    capsys.readouterr()
    assert main([*common, "--backend", "cupy", "--out", str(tmp_path / "gpu")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("robocal-uncertainty evaluate: error: backend 'cupy' is not available")
    assert not (tmp_path / "gpu").exists()
    # The recorded backend (one run: the numbers of each backend are the library tests' job).
    name = "numba" if HAS_NUMBA else "numpy"
    assert main([*common, "--backend", "auto", "--out", str(tmp_path / name)]) == 0
    assert f"backend {name} " in capsys.readouterr().out
    report = json.loads((tmp_path / name / "report.json").read_text())
    assert report["monte_carlo"]["backend"]["name"] == name
    assert report["monte_carlo"]["backend"]["requested"] == "auto"
    assert f"Monte Carlo backend: {name} " in (tmp_path / name / "report.md").read_text()
