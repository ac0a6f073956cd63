"""Small campaigns: the default statement holds (95 +- 4 % of held-out poses inside its 95 %
region) or flags itself as not trustworthy, on the shipped UR10 series and on a simulated
series with unmodelled joint errors (the rule is not tuned to either).

Slow (the UR10 check about 1 minute of CPU, 47 s of it the twelve 53-pose draws; under load the
simulated one took a fifth of its wall time): ``python -m pytest -m slow
test/uncertainty/test_small_campaigns_slow.py``.
The README's table comes from ``python benchmarks/small_campaign_study.py`` (more draws).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

ROOT = Path(__file__).resolve().parents[2]


def _study_module():
    spec = importlib.util.spec_from_file_location(
        "small_campaign_study", ROOT / "benchmarks" / "small_campaign_study.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _check(rows: list[dict[str, float]]) -> None:
    for r in rows:
        if r["flagged"] == r["draws"]:
            continue  # the statement says it cannot be trusted: honest whatever its coverage
        assert r["flagged"] == 0, r  # one rule per size (the residual dof depend only on n here)
        assert 0.91 <= r["inside"] <= 0.99, r
        assert 0.7 <= r["normalised_rms"] <= 1.15, r


UR10_DRAWS_53 = 12
"""53-pose draws of the UR10 series the check pools. Between draws (which poses train) the region's
coverage scatters by 2.8 % (standard deviation over 20 draws of the default statement, 1 000
trials each: ``python benchmarks/small_campaign_study.py --series ur10 --sizes 53 --draws 20
--trials 1000 --per-draw``), far more than within a draw, so the draws, not the trials, set the
check's own spread: 12 draws give 0.8 % (standard error) against the 1.6 % by which the 20 draws'
92.6 % clears the band's lower end; 2 draws gave 2.0 % and failed on draw 0 alone. The trials stay
at 1 000: at 300 every draw's region holds 0.8 % fewer held-out poses (a few hundred trials
understate the region), a bias the draws do not average out."""


@pytest.mark.slow
def test_small_ur10_campaigns_hold_or_are_flagged() -> None:
    study = _study_module()
    model = load_robot_model(resolve_robot_config("ur10"))
    campaign = read_tracker_csv(study.UR10_CSV)
    # 10 and 20 poses: below 96 residual dof, flagged whatever their coverage (the flag does not
    # depend on the trials: 200 do for it).
    flagged = study.study(model, campaign, (10, 20), draws=2, trials=200, seed=0)
    assert [r["flagged"] for r in flagged] == [2, 2]
    rows = study.study(model, campaign, (53,), draws=UR10_DRAWS_53, trials=1000, seed=0)
    assert rows[0]["flagged"] == 0
    _check(flagged + rows)


@pytest.mark.slow
def test_small_simulated_campaigns_hold_or_are_flagged() -> None:
    study = _study_module()
    model = load_robot_model(resolve_robot_config("ur10"))
    gear, sag = study.SIMULATED_ERRORS[0]
    campaign, u = study.simulated_series(model, gear, sag, seed=7)
    assert (u > 2e-5).all()  # a model error well above the tracker noise
    rows = study.study(model, campaign, (10, 53), draws=2, trials=1000, seed=0)
    assert [r["flagged"] for r in rows] == [2, 0]
    _check(rows)
