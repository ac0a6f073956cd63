"""Figures of an uncertainty evaluation (the reference paper's Figs. 5-11), one PNG per function.

Uses matplotlib's Agg backend and the object API (no pyplot state), so figures can be
written from worker threads and on machines without a display. Each function writes
its PNG and returns the path.

Layout uses fixed margins (in inches, so they hold at any figure size) instead of
``tight_layout``: measuring every tick label for ``tight_layout`` took 40 % of the time
of a figure, which adds up to tens of seconds over a report with 150 test
configurations. Reports with many configurations use :func:`plot_configuration_summary`
and :func:`plot_uncertainty_vs_reach` instead of one figure per configuration.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo.summary import OutputSummary
from robocal_uncertainty.report.configurations import ConfigurationSummary, summarize_configurations
from robocal_uncertainty.report.table2 import LENGTH_UNITS
from robocal_uncertainty.uncertainty.calibration import (
    CalibrationUncertainty,
)

__all__ = [
    "plot_axis_histograms",
    "plot_configuration_summary",
    "plot_lcurve",
    "plot_parameter_distributions",
    "plot_position_error",
    "plot_rotation_histograms",
    "plot_uncertainty_vs",
    "plot_uncertainty_vs_reach",
]

Array = NDArray[np.float64]
_DPI = 110
_AXES = ("x", "y", "z")


def _mark_summary(ax: Axes, summary: OutputSummary, scale: float) -> None:
    """Vertical lines of a histogram: the mean, the probabilistically symmetric and the shortest interval."""
    ax.axvline(summary.estimate * scale, color="k", lw=1.5, label="mean")
    sym = summary.probabilistically_symmetric
    ax.axvline(sym.low * scale, color="tab:blue", ls="--", lw=1.2, label="prob. symmetric")
    ax.axvline(sym.high * scale, color="tab:blue", ls="--", lw=1.2)
    sh = summary.shortest
    ax.axvline(sh.low * scale, color="tab:orange", ls=":", lw=1.5, label="shortest")
    ax.axvline(sh.high * scale, color="tab:orange", ls=":", lw=1.5)


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _margins(
    fig: Figure,
    *,
    left: float = 0.75,
    right: float = 0.15,
    bottom: float = 0.55,
    top: float = 0.4,
    wspace: float = 0.25,
    hspace: float = 0.2,
) -> None:
    """Fixed margins in inches (spacing as fractions of the mean axes size)."""
    w, h = fig.get_figwidth(), fig.get_figheight()
    fig.subplots_adjust(
        left=left / w,
        right=1 - right / w,
        bottom=bottom / h,
        top=1 - top / h,
        wspace=wspace,
        hspace=hspace,
    )


def _save(fig: Figure, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, format="png")
    return out


def _unit_scale(unit: str) -> float:
    try:
        return LENGTH_UNITS[unit]
    except KeyError as err:
        msg = f"unit must be one of {', '.join(LENGTH_UNITS)}, got {unit!r}"
        raise ConfigError(msg) from err


def _check_pose(result: CalibrationUncertainty, pose: int) -> None:
    if not 0 <= pose < len(result.poses):
        msg = f"pose index {pose} out of range for {len(result.poses)} test configuration(s)"
        raise ConfigError(msg)


def _pose_samples(result: CalibrationUncertainty, pose: int) -> Array:
    """Monte Carlo positions of one test configuration, shape (n_trials, 3) [m]."""
    _check_pose(result, pose)
    return np.asarray(result.samples[:, 3 * pose : 3 * pose + 3], dtype=np.float64)


def plot_axis_histograms(
    result: CalibrationUncertainty,
    path: str | Path,
    *,
    pose: int = 0,
    unit: str = "mm",
    bins: int = 60,
) -> Path:
    """Per-axis histograms of the tool position (the reference paper's Fig. 10).

    Each panel shows the Monte Carlo density, the mean, the probabilistically symmetric
    and the shortest coverage intervals, and the GUM normal pdf N(y_GUM, u_GUM²).

    Parameters
    ----------
    result : CalibrationUncertainty
    path : str or Path
        PNG file to write.
    pose : int
        Test configuration index.
    unit : {"mm", "m", "µm", "um"}
        Display unit of the positions.
    bins : int
        Histogram bins.

    Returns
    -------
    Path
    """
    s = _unit_scale(unit)
    samples = _pose_samples(result, pose) * s
    p = result.poses[pose]
    fig = _figure(12.0, 4.2)
    for j, name in enumerate(_AXES):
        ax = fig.add_subplot(1, 3, j + 1)
        col = samples[:, j]
        ax.hist(
            col,
            bins=bins,
            density=True,
            histtype="stepfilled",
            color="0.75",
            ec="0.5",
            label="Monte Carlo",
        )
        summary = p.axes[j]
        _mark_summary(ax, summary, s)
        u_gum = float(p.gum.standard_uncertainty[j]) * s
        if u_gum > 0:
            lo, hi = ax.get_xlim()
            grid = np.linspace(lo, hi, 400)
            pdf = stats.norm.pdf(grid, float(p.gum.estimate[j]) * s, u_gum)
            # With non-smooth sources on, the GUM covers only the smooth (noise) sources.
            label = "GUM normal" if p.gum.applicable else "GUM normal (noise sources only)"
            ax.plot(grid, pdf, color="tab:red", lw=1.3, label=label)
            ax.set_xlim(lo, hi)
        ax.ticklabel_format(axis="x", useOffset=False)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_xlabel(f"{name} / {unit}")
        ax.set_ylabel(f"density / {unit}⁻¹")
        ax.set_title(f"{name}: u = {summary.standard_uncertainty * s:.3g} {unit}")
        if j == 0:
            # One legend below the axes, so that it never hides the histograms.
            handles, labels = ax.get_legend_handles_labels()
            fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=len(labels), frameon=False)
    pct = 100 * result.coverage_probability
    fig.suptitle(
        f"Tool position, test configuration {pose + 1}: {result.n_trials} trials, p = {pct:g} %",
        fontsize=10,
    )
    _margins(fig, left=0.7, top=0.65, bottom=0.85, wspace=0.32)
    return _save(fig, path)


def plot_rotation_histograms(result: CalibrationUncertainty, path: str | Path, *, pose: int = 0) -> Path:
    """Per-axis histograms of the tool orientation's deviations from its mean, in mrad.

    Each panel (rx, ry, rz: rotations about the output frame's fixed axes) shows the Monte
    Carlo histogram, the mean (0), the probabilistically symmetric and the shortest coverage
    intervals and the GUM normal pdf, which is about the calibrated orientation (drawn at its
    offset from the mean). An undetermined axis gets an empty panel that says so.

    Parameters
    ----------
    result : CalibrationUncertainty
        With orientation (:attr:`PoseUncertainty.orientation` not None).
    path : str or Path
        PNG file to write.
    pose : int
        Test configuration index.

    Returns
    -------
    Path

    Raises
    ------
    ConfigError
        `pose` out of range, or the result has no orientation.
    """
    from robocal_uncertainty.core.rotation import rotation_log
    from robocal_uncertainty.uncertainty.calibration import ROTATION_AXES

    _check_pose(result, pose)
    o = result.poses[pose].orientation
    if o is None:
        msg = f"test configuration {pose + 1} has no orientation (evaluated for positions only)"
        raise ConfigError(msg)
    s = 1e3  # rad -> mrad
    calibrated_offset = rotation_log(o.calibrated_rotation @ o.mean_rotation.T)
    fig = _figure(12.0, 4.2)
    for j, name in enumerate(ROTATION_AXES):
        ax = fig.add_subplot(1, 3, j + 1)
        ax.set_xlabel(f"{name} / mrad")
        if not o.determined[j]:
            ax.text(0.5, 0.5, "undetermined", ha="center", va="center", transform=ax.transAxes)
            ax.set_yticks([])
            ax.set_title(f"{name}: no uncertainty statement")
            continue
        summary = o.axes[j]
        hist = summary.histogram
        edges = hist.edges * s
        density = hist.counts / max(float(hist.counts.sum()) * float(np.diff(edges).mean()), np.finfo(float).tiny)
        ax.stairs(density, edges, fill=True, color="0.75", ec="0.5", label="Monte Carlo")
        _mark_summary(ax, summary, s)
        u_gum = float(o.gum.standard_uncertainty[j]) * s
        if u_gum > 0:
            lo, hi = ax.get_xlim()
            grid = np.linspace(lo, hi, 400)
            centre = float(calibrated_offset[j]) * s
            label = "GUM normal" if o.gum.applicable else "GUM normal (noise sources only)"
            ax.plot(grid, stats.norm.pdf(grid, centre, u_gum), color="tab:red", lw=1.3, label=label)
            ax.set_xlim(lo, hi)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_ylabel("density / mrad⁻¹")
        ax.set_title(f"{name}: u = {summary.standard_uncertainty * s:.3g} mrad")
        if not fig.legends:
            handles, labels = ax.get_legend_handles_labels()
            fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=len(labels), frameon=False)
    pct = 100 * result.coverage_probability
    fig.suptitle(
        f"Tool orientation (deviation from the mean, frame {result.frame_id}), test configuration {pose + 1}: "
        f"{result.n_trials} trials, p = {pct:g} %",
        fontsize=10,
    )
    _margins(fig, left=0.7, top=0.65, bottom=0.85, wspace=0.32)
    return _save(fig, path)


def _log_ticks(axis: Axis) -> None:
    """Readable ticks on a log axis: labelled 1-2-5 ticks when it spans under two decades."""
    axis.axes.autoscale_view()
    lo, hi = sorted(axis.get_view_interval())
    if lo > 0 and hi / lo < 100.0:
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def plot_lcurve(calibration: IdentificationResult, path: str | Path) -> Path:
    """L-curve with the corner, the GCV minimum and the chosen lambda marked.

    Parameters
    ----------
    calibration : IdentificationResult
        Its ``lcurve`` (of the final linearisation) and ``lambda_``.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
    """
    lc = calibration.lcurve
    lams = np.asarray(lc.lambdas, dtype=np.float64)
    rho = np.asarray(lc.residual_norms, dtype=np.float64) * 1e6
    eta = np.asarray(lc.solution_norms, dtype=np.float64)
    gcv = np.asarray(lc.gcv, dtype=np.float64)
    ok = (rho > 0) & (eta > 0) & np.isfinite(rho) & np.isfinite(eta)
    if not ok.any():
        msg = "the calibration's L-curve has no positive finite points to plot"
        raise InputError(msg)
    lam = calibration.lambda_
    chosen = int(np.argmin(np.abs(np.log(np.maximum(lams, 1e-300)) - math.log(max(lam, 1e-300)))))
    fig = _figure(11.0, 4.2)
    ax = fig.add_subplot(1, 2, 1)
    ax.loglog(rho[ok], eta[ok], color="k", lw=1.2)
    marks = (
        (lc.corner_index, "o", "tab:blue", f"corner λ = {lc.corner_lambda:.3g}"),
        (lc.gcv_index, "s", "tab:green", f"GCV λ = {lc.gcv_lambda:.3g}"),
        (chosen, "*", "tab:red", f"chosen λ = {lam:.3g} ({calibration.lambda_method})"),
    )
    # Nested sizes: when two marks fall on the same point (corner = chosen) all stay visible.
    for (idx, marker, color, label), size in zip(marks, (15, 10, 6)):
        if ok[idx]:
            ax.loglog(
                rho[idx],
                eta[idx],
                marker,
                color=color,
                ms=size,
                mfc="none",
                mew=1.6,
                label=label,
            )
    for axis in (ax.xaxis, ax.yaxis):
        _log_ticks(axis)
    ax.set_xlabel("residual norm ‖b − A x_λ‖ / µm")
    ax.set_ylabel("solution norm ‖x_λ‖ (scaled)")
    ax.set_title("L-curve")
    ax.legend(fontsize=8)
    ax2 = fig.add_subplot(1, 2, 2)
    good = np.isfinite(gcv) & (gcv > 0) & (lams > 0)
    if good.any():
        ax2.loglog(lams[good], gcv[good], color="k", lw=1.2)
        if good[lc.gcv_index]:
            ax2.loglog(
                lams[lc.gcv_index],
                gcv[lc.gcv_index],
                "s",
                color="tab:green",
                mfc="none",
                ms=9,
                mew=1.8,
                label="GCV minimum",
            )
    if lam > 0:
        ax2.axvline(lam, color="tab:red", ls="--", label="chosen λ")
    if lc.corner_lambda > 0:
        ax2.axvline(lc.corner_lambda, color="tab:blue", ls=":", label="L-curve corner")
    ax2.set_xlabel("λ (scaled units)")
    ax2.set_ylabel("GCV(λ)")
    ax2.set_title("Generalised cross-validation")
    ax2.legend(fontsize=8)
    _margins(fig, left=0.85, wspace=0.3)
    return _save(fig, path)


def _mark_held(ax: Axes) -> None:
    """Mark a panel whose spread is the Tikhonov term's, not a measurement's, as the tables mark it."""
    ax.set_facecolor("0.93")
    ax.text(
        0.02,
        0.97,
        "held by\nregularisation",
        ha="left",
        va="top",
        transform=ax.transAxes,
        fontsize=6,
        color="tab:red",
        bbox={"facecolor": "white", "edgecolor": "none", "pad": 1.0},
    )
    for patch in ax.patches:
        patch.set_hatch("///")


def plot_parameter_distributions(
    result: CalibrationUncertainty,
    path: str | Path,
    *,
    bins: int = 40,
    columns: int = 6,
) -> Path:
    """Grid of histograms of the identified parameter errors (the reference paper's Fig. 5).

    Each panel is the Monte Carlo distribution of ``p − p_nominal`` for one estimated
    parameter, in µm for lengths and mdeg for angles, with the calibration's estimate
    marked.

    Parameters
    ----------
    result : CalibrationUncertainty
    path : str or Path
        PNG file to write.
    bins : int
        Histogram bins per panel.
    columns : int
        Panels per row.

    Returns
    -------
    Path
    """
    cal = result.calibration
    names = result.parameter_names
    k = len(names)
    if k == 0:
        msg = "the result has no estimated parameters to plot"
        raise InputError(msg)
    index = {n: i for i, n in enumerate(cal.parameter_names)}
    kinds = dict(zip(cal.model.layout.names, cal.model.layout.kinds))
    held = np.asarray(getattr(cal, "held_by_regularisation", np.zeros(len(cal.parameter_names), dtype=bool)))
    n_test = len(result.poses)
    values = np.asarray(result.samples[:, 3 * n_test : 3 * n_test + k], dtype=np.float64)
    cols = max(1, min(columns, k))
    rows = math.ceil(k / cols)
    fig = _figure(2.3 * cols, 2.0 * rows + 0.4)
    for j, name in enumerate(names):
        i = index[name]
        if kinds.get(name, "length") == "angle":
            scale, unit = 1e3 * 180.0 / math.pi, "mdeg"
        else:
            scale, unit = 1e6, "µm"
        err = (values[:, j] - cal.nominal[i]) * scale
        ax: Axes = fig.add_subplot(rows, cols, j + 1)
        ax.hist(err, bins=bins, histtype="stepfilled", color="0.7", ec="0.4", lw=0.5)
        ax.axvline((cal.estimate[i] - cal.nominal[i]) * scale, color="tab:red", lw=1.0)
        if held[i]:
            _mark_held(ax)
        ax.set_title(name + (" (held)" if held[i] else ""), fontsize=8)
        ax.set_xlabel(f"δ / {unit}", fontsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=6)
        ax.set_yticks([])
    fig.suptitle(
        f"Identified parameter errors p − p_nominal ({result.n_trials} trials; red: calibration)",
        fontsize=9,
    )
    fig.subplots_adjust(
        left=0.02,
        right=0.98,
        bottom=0.7 / fig.get_figheight(),
        top=1 - 0.75 / fig.get_figheight(),
        wspace=0.12,
        hspace=0.75,
    )
    return _save(fig, path)


def plot_position_error(
    result: CalibrationUncertainty,
    path: str | Path,
    *,
    pose: int = 0,
    bins: int = 60,
) -> Path:
    """Distribution of the position error |position − mean| in µm (the reference paper's Fig. 11).

    Parameters
    ----------
    result : CalibrationUncertainty
    path : str or Path
        PNG file to write.
    pose : int
        Test configuration index.
    bins : int
        Histogram bins.

    Returns
    -------
    Path
    """
    samples = _pose_samples(result, pose)
    dist = np.linalg.norm(samples - result.poses[pose].mean, axis=1) * 1e6
    p = result.coverage_probability
    q = float(np.quantile(dist, p))
    fig = _figure(6.5, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    ax.hist(dist, bins=bins, histtype="stepfilled", color="0.7", ec="0.4")
    ax.axvline(
        float(np.median(dist)),
        color="k",
        lw=1.2,
        label=f"median {np.median(dist):.3g} µm",
    )
    ax.axvline(q, color="tab:red", ls="--", lw=1.2, label=f"{100 * p:g} % quantile {q:.3g} µm")
    ax.set_xlabel("position error |p − p̄| / µm")
    ax.set_ylabel("trials")
    ax.set_title(f"Position error, test configuration {pose + 1} ({result.n_trials} trials)")
    ax.legend(fontsize=8)
    _margins(fig)
    return _save(fig, path)


def plot_uncertainty_vs(
    values: ArrayLike,
    u_xyz: ArrayLike,
    xlabel: str,
    path: str | Path,
    *,
    unit: str = "µm",
    reference: float | None = None,
    log_x: bool = False,
    title: str | None = None,
) -> Path:
    """Standard uncertainty per axis against a swept setting (the reference paper's Figs. 7-9).

    Parameters
    ----------
    values : array_like, shape (n_points,)
        The swept setting (lambda, number of equations, ...).
    u_xyz : array_like, shape (n_points, 3) [m]
        u(x), u(y), u(z) at each point.
    xlabel : str
        Label of `values`, with its unit.
    path : str or Path
        PNG file to write.
    unit : {"µm", "um", "mm", "m"}
        Display unit of the uncertainties.
    reference : float, optional
        Setting to mark with a vertical line (e.g. the calibration's lambda).
    log_x : bool
        Logarithmic x axis.
    title : str, optional

    Returns
    -------
    Path
    """
    s = _unit_scale(unit)
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    u = np.asarray(u_xyz, dtype=np.float64)
    if u.shape != (x.size, 3):
        msg = f"u_xyz must have shape ({x.size}, 3) to match values, got {u.shape}"
        raise InputError(msg)
    order = np.argsort(x)
    x, u = x[order], u[order] * s
    fig = _figure(6.8, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    for j, (name, color) in enumerate(zip(_AXES, ("tab:blue", "tab:orange", "tab:green"))):
        ax.plot(x, u[:, j], "o-", color=color, ms=4, label=f"u({name})")
    ax.plot(x, np.linalg.norm(u, axis=1), "s--", color="k", ms=4, label="u_pos = ‖u‖")
    if reference is not None and math.isfinite(reference):
        ax.axvline(reference, color="tab:red", ls=":", label="reference")
    if log_x:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"standard uncertainty / {unit}")
    ax.set_title(title or f"Uncertainty vs {xlabel}")
    # Legend below the axes: flat curves (u against lambda) run through any corner.
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=5, frameon=False)
    ax.grid(alpha=0.3)
    _margins(fig, bottom=0.95)
    return _save(fig, path)


_AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")


def _headroom(ax: Axes, values: Array) -> None:
    """y from 0 to 1.2 times the largest finite value, leaving room for the legend."""
    finite = values[np.isfinite(values)]
    top = float(finite.max()) if finite.size else 0.0
    if top > 0:
        ax.set_ylim(0.0, 1.2 * top)


def _points_style(n: int) -> dict[str, Any]:
    """Markers joined by thin lines for a few points, bare small markers for many."""
    if n <= 60:
        return {"marker": "o", "ms": 3.5, "lw": 0.8}
    return {"marker": ".", "ms": 3.0, "ls": "none"}


def plot_configuration_summary(
    result: CalibrationUncertainty,
    path: str | Path,
    *,
    summary: ConfigurationSummary | None = None,
    unit: str = "µm",
) -> Path:
    """Uncertainty per test configuration: u per axis, u_pos and the JCGM 102 region.

    Top panel: u(x), u(y), u(z) and u_pos against the configuration number (1-based),
    the worst configuration ringed. Bottom panel: the semi-axes of the JCGM 102 coverage
    ellipsoid of each configuration (largest, middle, smallest). One figure for any
    number of configurations.

    Parameters
    ----------
    result : CalibrationUncertainty
    path : str or Path
        PNG file to write.
    summary : ConfigurationSummary, optional
        Of `result`; computed when omitted.
    unit : {"µm", "um", "mm", "m"}
        Display unit of the uncertainties.

    Returns
    -------
    Path
    """
    s = _unit_scale(unit)
    summary = summary or summarize_configurations(result)
    n = len(summary)
    x = np.arange(1, n + 1)
    style = _points_style(n)
    fig = _figure(11.0, 6.8)
    ax = fig.add_subplot(2, 1, 1)
    for j, (name, color) in enumerate(zip(_AXES, _AXIS_COLORS)):
        ax.plot(x, summary.standard_uncertainty[:, j] * s, color=color, label=f"u({name})", **style)
    ax.plot(x, summary.position_uncertainty * s, color="k", label="u_pos", **style)
    w = summary.worst
    ax.plot(
        w + 1,
        summary.position_uncertainty[w] * s,
        "o",
        ms=11,
        mfc="none",
        mec="tab:red",
        mew=1.6,
        label=f"worst: configuration {w + 1}",
    )
    ax.set_ylabel(f"standard uncertainty / {unit}")
    pct = 100 * result.coverage_probability
    ax.set_title(
        f"Uncertainty of the tool position over {n} test configurations ({result.n_trials} trials, "
        f"frame {result.frame_id})",
        fontsize=10,
    )
    # Head room so the legend never hides the largest values.
    _headroom(ax, summary.position_uncertainty * s)
    ax.legend(fontsize=7, ncol=5, loc="upper right")
    ax.grid(alpha=0.3)
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
    semi = summary.region_semi_axes * s
    if np.isfinite(semi).any():
        for j, label in enumerate(("largest", "middle", "smallest")):
            ax2.plot(x, semi[:, j], color=("k", "0.45", "0.7")[j], label=f"{label} semi-axis", **style)
        _headroom(ax2, semi)
        ax2.legend(fontsize=7, ncol=3, loc="upper right")
    else:
        ax2.text(0.5, 0.5, "no JCGM 102 region (degenerate)", ha="center", va="center", transform=ax2.transAxes)
    ax2.set_ylabel(f"semi-axis / {unit}")
    ax2.set_title(f"JCGM 102 coverage ellipsoid (p = {pct:g} %)", fontsize=10)
    ax2.set_xlabel("test configuration")
    ax2.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax2.grid(alpha=0.3)
    _margins(fig, top=0.35, hspace=0.3)
    return _save(fig, path)


def plot_uncertainty_vs_reach(
    result: CalibrationUncertainty,
    path: str | Path,
    *,
    summary: ConfigurationSummary | None = None,
    unit: str = "µm",
) -> Path:
    """Standard uncertainty of every test configuration against its reach.

    The reach is the distance of the tool from the origin of the robot base frame
    (:attr:`ConfigurationSummary.reach`), in mm. u(x), u(y), u(z) and u_pos are drawn
    as points, the worst configuration ringed. Parameters and return value as in
    :func:`plot_configuration_summary`.
    """
    s = _unit_scale(unit)
    summary = summary or summarize_configurations(result)
    reach = summary.reach * 1e3
    fig = _figure(6.8, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    for j, (name, color) in enumerate(zip(_AXES, _AXIS_COLORS)):
        ax.plot(reach, summary.standard_uncertainty[:, j] * s, ".", color=color, ms=4, label=f"u({name})")
    ax.plot(reach, summary.position_uncertainty * s, "s", color="k", ms=3, label="u_pos")
    w = summary.worst
    ax.plot(
        reach[w],
        summary.position_uncertainty[w] * s,
        "o",
        ms=11,
        mfc="none",
        mec="tab:red",
        mew=1.6,
        label=f"worst: configuration {w + 1}",
    )
    ax.set_xlabel("reach: distance of the tool from the robot base / mm")
    ax.set_ylabel(f"standard uncertainty / {unit}")
    ax.set_title(f"Uncertainty vs reach ({len(summary)} test configurations)", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    _margins(fig)
    return _save(fig, path)
