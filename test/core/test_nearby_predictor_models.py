"""The Monte Carlo's fast predictor equals the full forward kinematics for every kind of model.

:class:`~robocal_uncertainty.core.kinematics.NearbyPoints` walks revolute chains; models read
from a URDF may have prismatic joints and a base-link mount. Whatever a measurement type's
``nearby_predictor`` returns must predict what ``predict`` predicts (or be None, and the
re-identification then uses ``predict``): a predictor that ignored the mount or a prismatic
joint would make every Monte Carlo trial of such a model silently wrong.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.urdf_model import load_urdf, robot_model_from_urdf

URDF_DIR = Path(__file__).resolve().parents[1] / "data" / "urdf"


def _models() -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = [
        (name, load_robot_model(resolve_robot_config(name))) for name in ("ur10", "paper_arm")
    ]
    out += [(path.name, robot_model_from_urdf(load_urdf(path), None, None)) for path in sorted(URDF_DIR.glob("*.urdf"))]
    return out


@pytest.mark.parametrize(("name", "model"), _models(), ids=[n for n, _ in _models()])
@pytest.mark.parametrize("measurement", [POINT, PoseMeasurement((1e-5,) * 3, (1e-4,) * 3)], ids=["points", "poses"])
def test_nearby_predictor_equals_predict(name: str, model: object, measurement: object) -> None:
    _ = name
    layout = model.layout  # type: ignore[attr-defined]
    rng = np.random.default_rng(7)
    p0 = model.parameter_vector() + rng.normal(0.0, 1e-3, len(layout.names))  # type: ignore[attr-defined]
    q0 = rng.uniform(-1.0, 1.0, (9, model.n_joints))  # type: ignore[attr-defined]
    predictor = measurement.nearby_predictor(layout, p0, q0)  # type: ignore[attr-defined]
    if predictor is None:
        assert any(layout.prismatic) or layout.has_mount  # only where the walk does not apply
        return
    p = p0 + rng.normal(0.0, 1e-6, (4, 1, len(p0)))
    q = q0 + rng.normal(0.0, 1e-6, (4, *q0.shape))
    want = measurement.predict(layout, p, q)  # type: ignore[attr-defined]
    assert np.abs(predictor(p, q) - want).max() < 1e-12
