"""Reports of an uncertainty evaluation: JSON, the robot paper's Table 2, figures, sweeps, documents."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.report.configurations import (
        DEFAULT_HISTOGRAMS,
        DETAIL_LIMIT,
        ConfigurationSummary,
        select_configurations,
        summarize_configurations,
        write_configurations_csv,
    )
    from robocal_uncertainty.report.document import REPORT_FILES, write_report
    from robocal_uncertainty.report.json_report import (
        REPORT_FORMAT,
        REPORT_FORMAT_VERSION,
        read_report_json,
        uncertainty_to_dict,
        write_report_json,
    )
    from robocal_uncertainty.report.map_report import MapReportFiles, WeakestRegion, weakest_region, write_map_report
    from robocal_uncertainty.report.plots import (
        plot_axis_histograms,
        plot_configuration_summary,
        plot_lcurve,
        plot_parameter_distributions,
        plot_position_error,
        plot_rotation_histograms,
        plot_uncertainty_vs,
        plot_uncertainty_vs_reach,
    )
    from robocal_uncertainty.report.section_report import (
        SectionReportFiles,
        format_section_table,
        write_section_report,
    )
    from robocal_uncertainty.report.table2 import (
        format_budget,
        format_table2,
        round_to_uncertainty,
    )
    from robocal_uncertainty.uncertainty.sweeps import Sweep, sweep_equations, sweep_lambda

__all__ = [
    "DEFAULT_HISTOGRAMS",
    "DETAIL_LIMIT",
    "REPORT_FILES",
    "REPORT_FORMAT",
    "REPORT_FORMAT_VERSION",
    "ConfigurationSummary",
    "MapReportFiles",
    "SectionReportFiles",
    "Sweep",
    "WeakestRegion",
    "format_budget",
    "format_section_table",
    "format_table2",
    "plot_axis_histograms",
    "plot_configuration_summary",
    "plot_lcurve",
    "plot_parameter_distributions",
    "plot_position_error",
    "plot_rotation_histograms",
    "plot_uncertainty_vs",
    "plot_uncertainty_vs_reach",
    "read_report_json",
    "round_to_uncertainty",
    "select_configurations",
    "summarize_configurations",
    "sweep_equations",
    "sweep_lambda",
    "uncertainty_to_dict",
    "weakest_region",
    "write_configurations_csv",
    "write_map_report",
    "write_report",
    "write_report_json",
    "write_section_report",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
