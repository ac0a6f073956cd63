"""The demo's sources come from the registry's roles, and are the paper's five."""

from __future__ import annotations

from robocal_uncertainty.cli.demo import demo_sources


def test_demo_draws_the_papers_five_sources_in_their_order() -> None:
    """Reference: Jiang et al.'s Table 2 scenario, tracker and encoder noise, the regularisation
    parameter, the pose count and the pose choice (the demo's list before the registry named them)."""
    assert demo_sources() == ("tracker", "encoder", "lambda", "n_poses", "pose_choice")
