"""Latency from a new calibration sample to the published uncertainty, as the nodes compute it.

Samples of a campaign are added one by one. For each of the last `--last` samples the path of
the two nodes is timed from the sample's arrival to the uncertainty ready to publish:

- calibration node: ``SampleStore.add``, then ``store.pipeline(...).calibrate()``;
- uncertainty node: ``SampleStore.add``, ``SampleStore.pipeline_of(...)``, ``calibrate()``,
  :func:`robocal_uncertainty.app.evaluate` and the messages (``uncertainty_to_msgs``,
  ``pose_with_covariance``, ``uncertainty_markers``).

Each Monte Carlo setting (fixed 2e4 trials and the adaptive procedure, the node's default
``trials: 0``) runs in three ways, in turn for every sample so that the load of the machine
falls on all of them alike:

- ``1 worker``: trial blocks in the node's process (``workers: 1``), the baseline of the ratios;
- ``2 workers, new pool``: 2 processes started for each evaluation (the node before issue 12);
- ``2 workers, kept pool``: a :class:`~robocal_uncertainty.montecarlo.executor.WorkerPool`
  started once (what the node does now).

Prints the median and the max latency over the last samples and each median's ratio to the
1-worker median of the same setting; the results of the three ways are checked to be equal
bit for bit. Nothing here is a pass/fail test on times: the machine's load average is printed
with them.

Campaigns: ``sim`` (default), a 50-pose simulated campaign of the paper arm in the tracker
frame at the uncertainty node's default settings (tracker 5 um, encoder 0.005 deg, the seed's
test configuration); ``ur10``, the first `--poses` poses of the shipped UR10 laser-tracker data.

Usage: ``python benchmarks/bench_latency.py [--campaign sim|ur10] [--poses 50] [--last 10]
[--settings 20000,auto]``
"""

from __future__ import annotations

import os

# As the nodes do: one BLAS thread (see robocal_uncertainty/nodes/uncertainty_node.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.app import evaluate
from robocal_uncertainty.bagio.messages import pose_with_covariance, uncertainty_to_msgs
from robocal_uncertainty.core import EncoderNoise, SimulationSettings, TrackerNoise, load_robot_model, simulate_campaign
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.importers import read_tracker_csv
from robocal_uncertainty.montecarlo.executor import RunContext, WorkerPool
from robocal_uncertainty.pipeline.markers import uncertainty_markers
from robocal_uncertainty.pipeline.sample_store import SampleStore
from robocal_uncertainty.report.references import PAPER_TEST_JOINTS_DEG
from robocal_uncertainty.uncertainty import EvaluationSettings, UncertaintySettings

ROOT = Path(__file__).resolve().parents[1]
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
UR10_TEST = np.array([[0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075]])  # as test_trust_on_real_robots
MODES = ("1 worker", "2 workers, new pool", "2 workers, kept pool")


def node_settings() -> UncertaintySettings:
    """The uncertainty node's settings at its parameter defaults (see ``UncertaintyNode._options``)."""
    return UncertaintySettings(
        sources=("tracker", "encoder"),
        tracker_noise=TrackerNoise(a=5.0 * 1e-6, b=0.0),
        encoder_noise=EncoderNoise(half_width=float(np.radians(0.005))),
        lambda_range=None,
        min_poses=None,
        subset_size=None,
        tracker_xyz=(2.0, 0.5, 0.3),
    )


def campaign_of(name: str, n_poses: int) -> tuple[RobotModel, Campaign, np.ndarray]:
    """Model, campaign and test configurations [rad] of the chosen campaign."""
    if name == "ur10":
        model = load_robot_model(resolve_robot_config("ur10"))
        campaign = read_tracker_csv(UR10_CSV).subset(np.arange(n_poses))
        return model, campaign, UR10_TEST
    model = load_robot_model(resolve_robot_config("paper_arm"))
    campaign = simulate_campaign(model, SimulationSettings(n_poses=n_poses, frame="tracker"), seed=1).campaign
    return model, campaign, np.radians([PAPER_TEST_JOINTS_DEG])


def samples_of(campaign: Campaign) -> list[CalibrationSample]:
    """One sample per pose, 5 s apart (stamps are made up when the campaign has none)."""
    stamps = campaign.stamps_ns
    if stamps is None:
        stamps = 1_700_000_000_000_000_000 + 5_000_000_000 * np.arange(campaign.n_poses, dtype=np.int64)
    std = campaign.point_std if campaign.point_std is not None else np.full((campaign.n_poses, 3), 5e-6)
    return [
        CalibrationSample(
            stamp_ns=int(stamps[i]),
            frame_id=campaign.frame_id,
            joint_names=campaign.joint_names,
            joint_positions=campaign.joint_positions[i],
            joint_position_std=np.zeros(len(campaign.joint_names)),
            point=campaign.points[i, :3],
            point_covariance=np.diag(np.square(std[i, :3])),
            joint_state_count=1,
            tracker_point_count=1,
        )
        for i in range(campaign.n_poses)
    ]


class NodePath:
    """The calibration and uncertainty nodes' work for one way of running the trials."""

    def __init__(self, model: RobotModel, options: EvaluationSettings, mode: str) -> None:
        self.model = model
        self.options = options
        self.mode = mode
        self.calibration_store = SampleStore(model)
        self.uncertainty_store = SampleStore(model)
        self.pool = (
            WorkerPool(2, preload=("robocal_uncertainty.uncertainty.calibration.evaluation",))
            if "kept" in mode
            else None
        )
        if self.pool is not None:
            self.pool.start()  # the node starts its pool before the first sample

    def add(self, sample: CalibrationSample, *, evaluated: bool) -> np.ndarray | None:
        """Both nodes take the sample; with `evaluated`, calibrate and evaluate as they do."""
        self.calibration_store.add(sample)
        self.uncertainty_store.add(sample)
        if not evaluated:
            return None
        self.calibration_store.pipeline(options=self.options).calibrate()  # the calibration node
        samples = self.uncertainty_store.first(len(self.uncertainty_store))
        pipeline = SampleStore.pipeline_of(self.model, samples, options=self.options)
        calibration = pipeline.calibrate()
        campaign = pipeline.campaign
        assert campaign is not None
        if self.pool is not None:
            run = evaluate(
                self.model,
                campaign,
                self.options,
                calibration=calibration,
                run=RunContext(executor=self.pool.executor()),
            )
        else:
            workers = 1 if self.mode == "1 worker" else 2
            run = evaluate(self.model, campaign, self.options, calibration=calibration, run=RunContext(workers=workers))
        result = run.uncertainty
        uncertainty_to_msgs(result, stamp_ns=sample.stamp_ns, frame_id=result.frame_id)
        for pose in result.poses:
            pose_with_covariance(pose, undetermined_variance=1e6)
        uncertainty_markers(result, campaign_points=campaign.points, campaign_frame=campaign.frame, target_size_m=0.05)
        return np.asarray(result.samples)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()


def timed(path: NodePath, sample: CalibrationSample, *, evaluated: bool) -> tuple[float, float, np.ndarray | None]:
    """Wall and CPU (this process) seconds of ``path.add(sample)``, and its trial values."""
    wall, cpu = time.perf_counter(), time.process_time()
    value = path.add(sample, evaluated=evaluated)
    return time.perf_counter() - wall, time.process_time() - cpu, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", choices=("sim", "ur10"), default="sim")
    parser.add_argument("--poses", type=int, default=50, help="samples of the campaign (default 50)")
    parser.add_argument("--last", type=int, default=10, help="samples timed at the end of the campaign")
    parser.add_argument("--settings", default="20000,auto", help="comma list of trial counts or 'auto'")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    model, campaign, test_joints = campaign_of(args.campaign, args.poses)
    samples = samples_of(campaign)
    first = len(samples) - args.last
    print(
        f"campaign {args.campaign}: {campaign.n_poses} poses of {model.name}, "
        f"{len(test_joints)} test configuration(s); timing samples {first + 1}..{len(samples)}; {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.2f} at start"
    )
    for setting in args.settings.split(","):
        trials: int | str = "auto" if setting.strip() == "auto" else int(setting)
        options = EvaluationSettings(
            test_joints=test_joints, uncertainty=node_settings(), trials=trials, seed=args.seed
        )
        paths = [NodePath(model, options, mode) for mode in MODES]
        wall: dict[str, list[float]] = {mode: [] for mode in MODES}
        cpu: dict[str, list[float]] = {mode: [] for mode in MODES}
        n_trials: list[int] = []
        loads = []
        try:
            for i, sample in enumerate(samples):
                # The sample before the timed ones warms every path up (imports, first pool use).
                evaluated = i >= first - 1
                values = []
                for path in paths:
                    w, c, value = timed(path, sample, evaluated=evaluated)
                    values.append(value)
                    if i >= first:
                        wall[path.mode].append(w)
                        cpu[path.mode].append(c)
                if i >= first:
                    assert values[0] is not None
                    for value in values[1:]:
                        assert value is not None and np.array_equal(value, values[0]), "results differ between modes"
                    n_trials.append(values[0].shape[0])
                    loads.append(os.getloadavg()[0])
        finally:
            for path in paths:
                path.close()
        base = float(np.median(wall[MODES[0]]))
        label = f"fixed {trials} trials" if trials != "auto" else f"adaptive (trials {min(n_trials)}..{max(n_trials)})"
        print(f"\n{label}: sample -> uncertainty ready to publish, last {args.last} samples [s]")
        for mode in MODES:
            med = float(np.median(wall[mode]))
            print(
                f"  {mode:22s} median {med:6.2f}  max {max(wall[mode]):6.2f}  ratio to 1 worker {med / base:5.2f}  "
                f"(CPU of this process: median {np.median(cpu[mode]):5.2f})"
            )
        print(f"  results identical in all three ways; load average during the run {min(loads):.2f}..{max(loads):.2f}")


if __name__ == "__main__":
    main()
