"""The validated level's fold path gives what a full verification of the fold gives.

``fold_level`` skips the null draws and the verdict's statistics, and assembles the field's
prediction covariance once per check, rotated per iteration. Both are checked here against the
slow path on real UR10 poses (series D): the level numbers and the covariance equal to rounding
(``ModelErrorField.prediction_covariance``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import EncoderNoise, TrackerNoise, identify, load_robot_model
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.importers import read_tracker_csv
from robocal_uncertainty.uncertainty.sessions import verification
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sessions.verification import fold_level, verify_session

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fold():
    """A 53-pose calibration of series D with its field, a fold of it, and a 20-pose check of the rest."""
    model = load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml")
    campaign = read_tracker_csv(ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv")
    campaign = campaign.reorder_joints(model.joint_names)
    order = np.random.default_rng(5).permutation(campaign.n_poses)
    train = campaign.subset(np.sort(order[:53]))
    tn, en = TrackerNoise(), EncoderNoise()
    reference, _ = session_state(identify(model, train), train, tn, en)
    assert reference.model_error_field is not None  # the real series needs its field
    fold_train = train.subset(np.arange(10, 53))
    cal = identify(model, fold_train, accept_unconverged=True)
    state, _ = session_state(cal, fold_train, tn, en, model_error_from=reference)
    return cal.model, state, campaign.subset(np.sort(order[60:80]))


def test_fold_level_equals_the_verification_of_the_fold(fold) -> None:
    model, state, check = fold
    full = verify_session(model, state, check, retool=True, null_trials=100)
    quick = fold_level(model, state, check, retool=True)
    # The fold path assembles the field's covariance its own way: equal to rounding.
    assert (quick.level_dof, quick.n_poses) == (full.level_dof, full.n_poses)
    assert quick.level == pytest.approx(full.level, rel=1e-11)
    assert quick.level_trace == pytest.approx(full.level_trace, rel=1e-11)
    assert quick.level_z is not None and full.level_z is not None
    np.testing.assert_allclose(quick.level_z, full.level_z, rtol=0.0, atol=1e-9)


def test_field_prediction_equals_the_fields_own_covariance(fold) -> None:
    model, state, check = fold
    setup, p = verification._prepare(model, state, check, True, None, None, rotated_field=True)
    p[setup.free] += np.random.default_rng(1).normal(scale=1e-3, size=setup.free.size)  # a rotated tracker
    _, jac = forward_points_and_jacobian(setup.layout, p, setup.q)
    r_wb = rpy_to_matrix(p[setup.b0 + 3 : setup.b0 + 6])
    jk = jac[:, :, setup.kin].reshape(3 * setup.n, setup.kin.size)
    assert setup.field_cross is not None and abs(np.trace(r_wb) - 3.0) > 1e-3
    expected = state.model_error_field.prediction_covariance(
        setup.q, state.model_error_covariance, r_wb, jk, setup.kin_names
    )
    got = verification._field_prediction(setup, r_wb, jk)
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12 * np.max(np.abs(expected)))
