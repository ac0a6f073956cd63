"""Reports of an uncertainty evaluation: JSON, seed Table 2, figures, sweeps, documents."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.report.document import REPORT_FILES, write_report
    from robocal_uncertainty.report.json_report import (
        REPORT_FORMAT,
        REPORT_FORMAT_VERSION,
        read_report_json,
        uncertainty_to_dict,
        write_report_json,
    )
    from robocal_uncertainty.report.plots import (
        plot_axis_histograms,
        plot_lcurve,
        plot_parameter_distributions,
        plot_position_error,
        plot_uncertainty_vs,
    )
    from robocal_uncertainty.report.table2 import (
        format_budget,
        format_table2,
        round_to_uncertainty,
    )
    from robocal_uncertainty.uncertainty.sweeps import Sweep, sweep_equations, sweep_lambda

__all__ = [
    "REPORT_FILES",
    "REPORT_FORMAT",
    "REPORT_FORMAT_VERSION",
    "Sweep",
    "format_budget",
    "format_table2",
    "plot_axis_histograms",
    "plot_lcurve",
    "plot_parameter_distributions",
    "plot_position_error",
    "plot_uncertainty_vs",
    "read_report_json",
    "round_to_uncertainty",
    "sweep_equations",
    "sweep_lambda",
    "uncertainty_to_dict",
    "write_report",
    "write_report_json",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
