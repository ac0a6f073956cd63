"""Application services: one function per user job.

The command line, the ROS 2 nodes and the tests call these; they parse, print or publish,
and nothing else. ``evaluate`` calibrates a campaign and gives its Monte Carlo uncertainty,
budget and sweeps; ``replay`` turns a raw bag into a campaign and evaluates it the same way;
``validate`` checks an uncertainty statement on held-out measurements; ``simulate`` writes a
simulated campaign and its truth; ``tool_points`` gives the tool positions of a nominal or
calibrated model in a named frame. ``output_paths`` checks output files and report
directories before any work (one overwrite rule).

Modules are named after what they hold (``evaluation``, ``bag_replay``), never after an
exported function: importing a submodule binds its name on the package, which would hide
a lazily exported function of the same name.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.app.bag_replay import ReplayEvaluation, replay
    from robocal_uncertainty.app.compensation import Compensation, compensate
    from robocal_uncertainty.app.evaluation import Evaluation, evaluate
    from robocal_uncertainty.app.forward_kinematics import ToolPoints, tool_points
    from robocal_uncertainty.app.pose_suggestion import PoseSuggestion, Suggestions, suggest_poses
    from robocal_uncertainty.app.section_inspection import SectionInspection, inspect_section, section_demo
    from robocal_uncertainty.app.simulation import SimulationFiles, simulate
    from robocal_uncertainty.app.validation import validate
    from robocal_uncertainty.montecarlo.executor import RunContext
    from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = [
    "Compensation",
    "Evaluation",
    "EvaluationSettings",
    "PoseSuggestion",
    "ReplayEvaluation",
    "RunContext",
    "SectionInspection",
    "SimulationFiles",
    "Suggestions",
    "ToolPoints",
    "compensate",
    "evaluate",
    "inspect_section",
    "replay",
    "section_demo",
    "simulate",
    "suggest_poses",
    "tool_points",
    "validate",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
