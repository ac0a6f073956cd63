"""Application services: one function per user job.

The command line, the ROS 2 nodes and the tests call these; they parse, print or publish,
and nothing else. ``evaluate`` calibrates a campaign and gives its Monte Carlo uncertainty,
budget and sweeps; ``replay`` turns a raw bag into a campaign and evaluates it the same way.

Modules are named after what they hold (``evaluation``, ``bag_replay``), never after an
exported function: importing a submodule binds its name on the package, which would hide
a lazily exported function of the same name.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.app.bag_replay import ReplayEvaluation, replay
    from robocal_uncertainty.app.evaluation import Evaluation, evaluate
    from robocal_uncertainty.uncertainty.options import EvaluationOptions

__all__ = ["Evaluation", "EvaluationOptions", "ReplayEvaluation", "evaluate", "replay"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
