"""Report of a workspace uncertainty map: a table, summary plots and where it is weakest.

Written for thousands of configurations in seconds: one CSV row per configuration, one
JSON document (run metadata, summary statistics, the weakest configurations and every
row as columns), one PNG of four scatter panels (top and side views of the workspace coloured
by u_pos, u_pos against reach and against the distance from the nearest calibration pose)
and a short Markdown note saying where the calibration is weakest. No per-configuration
figure is drawn.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.workspace_map import WorkspaceMap

__all__ = ["MapReportFiles", "WeakestRegion", "weakest_region", "write_map_report"]

Array = NDArray[np.float64]
_UM = 1e6
_MM = 1e3


@dataclass(frozen=True)
class MapReportFiles:
    """Paths written by :func:`write_map_report`."""

    table_csv: Path
    json: Path
    markdown: Path
    figure: Path


@dataclass(frozen=True)
class WeakestRegion:
    """Where the map's position uncertainty is largest.

    Attributes
    ----------
    fraction : float
        Share of configurations counted as weakest (the top ``fraction`` by u_pos).
    indices : ndarray of int, shape (m,)
        0-based weakest configurations, worst first.
    threshold : float [m]
        Smallest u_pos among them.
    median_u, p95_u, max_u : float [m]
        Median, 95th percentile and maximum of u_pos over the whole map.
    centroid : ndarray, shape (3,) [m]
        Mean tool position of the weakest configurations (output frame).
    reach_weak, reach_all : (float, float) [m]
        Median reach of the weakest configurations and of all.
    nearest_weak, nearest_all : (float, float) [m]
        Median distance from the nearest calibration pose, weakest and all.
    rho_reach, rho_nearest : float
        Spearman rank correlation of u_pos with reach and with that distance (NaN for
        fewer than three configurations or a constant column).
    """

    fraction: float
    indices: NDArray[np.intp]
    threshold: float
    median_u: float
    p95_u: float
    max_u: float
    centroid: Array
    reach_weak: float
    reach_all: float
    nearest_weak: float
    nearest_all: float
    rho_reach: float
    rho_nearest: float


def _spearman(a: Array, b: Array) -> float:
    if a.size < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return math.nan
    return float(stats.spearmanr(a, b)[0])


def weakest_region(workspace_map: WorkspaceMap, fraction: float = 0.1) -> WeakestRegion:
    """Summarise the weakest ``fraction`` of the map's configurations (at least one).

    Parameters
    ----------
    workspace_map : WorkspaceMap
    fraction : float
        In (0, 1].

    Returns
    -------
    WeakestRegion
    """
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0.0 < fraction <= 1.0:
        msg = f"fraction of weakest configurations must be in (0, 1], got {fraction!r}"
        raise ConfigError(msg)
    u = workspace_map.position_uncertainty
    count = max(1, math.ceil(fraction * u.size))
    worst = workspace_map.order[:count]
    return WeakestRegion(
        fraction=float(fraction),
        indices=worst,
        threshold=float(u[worst].min()),
        median_u=float(np.median(u)),
        p95_u=float(np.percentile(u, 95)),
        max_u=float(u.max()),
        centroid=workspace_map.positions[worst].mean(axis=0),
        reach_weak=float(np.median(workspace_map.reach[worst])),
        reach_all=float(np.median(workspace_map.reach)),
        nearest_weak=float(np.median(workspace_map.nearest_pose_distance[worst])),
        nearest_all=float(np.median(workspace_map.nearest_pose_distance)),
        rho_reach=_spearman(u, workspace_map.reach),
        rho_nearest=_spearman(u, workspace_map.nearest_pose_distance),
    )


def _num(value: float, scale: float) -> str:
    v = float(value) * scale
    return f"{v:.9g}" if math.isfinite(v) else ""


def _write_csv(path: Path, wmap: WorkspaceMap) -> Path:
    header = ["configuration", *(f"{name}_deg" for name in wmap.joint_names)]
    header += [f"{a}_mm" for a in "xyz"] + ["reach_mm", "nearest_pose_mm"]
    header += [f"u_{a}_um" for a in "xyz"] + ["u_pos_um", "region_a1_um", "region_a2_um", "region_a3_um"]
    fielded = wmap.field_correction is not None and wmap.field_std_ratio is not None
    if fielded:
        header += [f"field_d{a}_um" for a in "xyz"] + ["field_std_ratio"]
    degrees = np.degrees(wmap.configurations)
    with path.open("w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for i in range(len(wmap)):
            row = [str(i + 1), *(f"{v:.6f}" for v in degrees[i])]
            row += [_num(v, _MM) for v in wmap.positions[i]]
            row += [_num(wmap.reach[i], _MM), _num(wmap.nearest_pose_distance[i], _MM)]
            row += [_num(v, _UM) for v in wmap.standard_uncertainty[i]]
            row += [_num(wmap.position_uncertainty[i], _UM), *(_num(v, _UM) for v in wmap.region_semi_axes[i])]
            if wmap.field_correction is not None and wmap.field_std_ratio is not None:
                row += [*(_num(v, _UM) for v in wmap.field_correction[i]), f"{wmap.field_std_ratio[i]:.4f}"]
            writer.writerow(row)
    return path


def _finite_or_none(values: Array) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=np.float64).ravel()]


def _metadata(wmap: WorkspaceMap) -> dict[str, Any]:
    return {
        "robot": wmap.calibration.model.name,
        "n_configurations": len(wmap),
        "n_trials": wmap.n_trials,
        "n_dropped": wmap.n_dropped,
        "seed": wmap.seed,
        "block_size": wmap.block_size,
        "backend": None if wmap.backend is None else wmap.backend.describe(),
        "sources": list(wmap.settings.sources),
        "frame": wmap.frame,
        "frame_id": wmap.frame_id,
        "coverage_probability": wmap.coverage_probability,
    }


def _write_json(path: Path, wmap: WorkspaceMap, weak: WeakestRegion) -> Path:
    document = {
        "units": {"joints": "rad", "length": "m"},
        **_metadata(wmap),
        "summary": {
            "median_u_pos": weak.median_u,
            "p95_u_pos": weak.p95_u,
            "max_u_pos": weak.max_u,
            "weakest_fraction": weak.fraction,
            "weakest_threshold_u_pos": weak.threshold,
            "weakest_configurations": [int(i) + 1 for i in weak.indices],
            "weakest_centroid": _finite_or_none(weak.centroid),
            "median_reach_weakest": weak.reach_weak,
            "median_reach_all": weak.reach_all,
            "median_nearest_pose_weakest": weak.nearest_weak,
            "median_nearest_pose_all": weak.nearest_all,
            "spearman_u_pos_reach": None if math.isnan(weak.rho_reach) else weak.rho_reach,
            "spearman_u_pos_nearest_pose": None if math.isnan(weak.rho_nearest) else weak.rho_nearest,
        },
        "joint_names": list(wmap.joint_names),
        "configurations": np.asarray(wmap.configurations).tolist(),
        "positions": np.asarray(wmap.positions).tolist(),
        "standard_uncertainty": np.asarray(wmap.standard_uncertainty).tolist(),
        "position_uncertainty": np.asarray(wmap.position_uncertainty).tolist(),
        "reach": np.asarray(wmap.reach).tolist(),
        "nearest_pose_distance": np.asarray(wmap.nearest_pose_distance).tolist(),
        "region_configurations": [int(i) + 1 for i in wmap.region_configurations],
        "region_semi_axes": [_finite_or_none(row) for row in wmap.region_semi_axes[wmap.region_configurations]],
        "warnings": list(wmap.warnings),
    }
    if wmap.field_correction is not None and wmap.field_std_ratio is not None:
        document["field_correction"] = {
            "correction": np.asarray(wmap.field_correction).tolist(),
            "std_ratio": np.asarray(wmap.field_std_ratio).tolist(),
            "note": "positions include the model-error field's conditional mean (kriging); a URDF cannot carry it",
        }
    path.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    return path


def _plot(path: Path, wmap: WorkspaceMap, weak: WeakestRegion) -> Path:
    fig = Figure(figsize=(11.0, 8.5), dpi=100)
    FigureCanvasAgg(fig)
    u = wmap.position_uncertainty * _UM
    pos = wmap.positions
    # Low u drawn first so the weakest configurations stay visible on top.
    order = np.argsort(u, kind="stable")
    size = 14.0 if len(wmap) <= 500 else 5.0
    worst = weak.indices[: min(10, weak.indices.size)]
    panels = [
        (pos[:, 0], pos[:, 1], "x / m", "y / m", "top view (x-y)"),
        (pos[:, 0], pos[:, 2], "x / m", "z / m", "side view (x-z)"),
        (wmap.reach, u, "reach from the base origin / m", "u_pos / µm", "u_pos against reach"),
        (
            wmap.nearest_pose_distance * _MM,
            u,
            "distance from the nearest calibration pose / mm",
            "u_pos / µm",
            "u_pos against extrapolation",
        ),
    ]
    scatter = None
    for k, (x, y, xlabel, ylabel, title) in enumerate(panels):
        ax = fig.add_subplot(2, 2, k + 1)
        scatter = ax.scatter(x[order], y[order], c=u[order], s=size, cmap="viridis", linewidths=0)
        ax.scatter(x[worst], y[worst], s=40, facecolors="none", edgecolors="tab:red", label="10 weakest")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        if k < 2:
            ax.set_aspect("equal", adjustable="datalim")
    fig.subplots_adjust(left=0.07, right=0.84, bottom=0.07, top=0.9, hspace=0.32, wspace=0.25)
    if scatter is not None:
        fig.colorbar(scatter, ax=fig.axes, shrink=0.8, label="u_pos / µm")
    fig.axes[0].legend(fontsize=8, loc="best")
    fig.suptitle(
        f"{wmap.calibration.model.name}: u_pos at {len(wmap)} configurations, "
        f"{wmap.n_trials} trials, random seed {wmap.seed}, frame {wmap.frame_id}",
        fontsize=11,
    )
    fig.savefig(path, format="png")
    return path


def _trend(rho: float, what: str) -> str:
    if math.isnan(rho):
        return f"no trend with {what} can be stated"
    if abs(rho) < 0.2:
        return f"u_pos shows no clear trend with {what} (Spearman ρ = {rho:.2f})"
    strength = "strongly" if abs(rho) >= 0.7 else "moderately" if abs(rho) >= 0.4 else "weakly"
    direction = "grows" if rho > 0 else "falls"
    return f"u_pos {strength} {direction} with {what} (Spearman ρ = {rho:.2f})"


def _field_lines(wmap: WorkspaceMap) -> list[str]:
    """Where the field's correction knows the error and where it widens the statement."""
    if wmap.field_correction is None or wmap.field_std_ratio is None:
        return []
    ratio = np.asarray(wmap.field_std_ratio)
    size = np.linalg.norm(wmap.field_correction, axis=1) * _UM
    far = ratio >= 0.9
    return [
        "## The model-error field's correction",
        "",
        "Positions include the field's conditional mean given the calibration residuals (kriging; "
        f"median size {np.median(size):.1f} µm, largest {np.max(size):.1f} µm) and the statement its kriging "
        "covariance. The std ratio (kriging std over the field's uncorrected std) is near 0 next to a "
        "calibration pose and 1 far from all of them, where the correction knows nothing and the field "
        f"widens the statement: median {np.median(ratio):.2f}, {np.mean(far):.0%} of the configurations at 0.9 "
        f"or more (Spearman ρ of the ratio with the distance from the nearest calibration pose "
        f"{_spearman(ratio, wmap.nearest_pose_distance):.2f}). A URDF or UR export cannot carry this correction; "
        "the calibration file does.",
        "",
    ]


def _markdown(wmap: WorkspaceMap, weak: WeakestRegion, files: tuple[str, str, str], worst: int) -> str:
    meta = _metadata(wmap)
    z_weak = np.percentile(wmap.positions[weak.indices, 2], [5, 95])
    z_all = np.percentile(wmap.positions[:, 2], [5, 95])
    lines = [
        f"# Workspace uncertainty map: {meta['robot']}",
        "",
        f"{len(wmap)} configurations, {wmap.n_trials} Monte Carlo trials (random seed {wmap.seed}, block size "
        f"{wmap.block_size}), sources {', '.join(wmap.settings.sources)}, positions in frame "
        f"`{wmap.frame_id}` ({wmap.frame}). Each trial re-identifies once and evaluates every configuration"
        f"{'' if wmap.backend is None else f' (trial kernels: {wmap.backend.describe()})'}.",
        "",
        f"u_pos = sqrt(u(x)² + u(y)² + u(z)²): median {weak.median_u * _UM:.1f} µm, 95th percentile "
        f"{weak.p95_u * _UM:.1f} µm, maximum {weak.max_u * _UM:.1f} µm.",
        "",
        "## Where the calibration is weakest",
        "",
        f"The weakest {weak.fraction:.0%} ({weak.indices.size} configurations, u_pos ≥ {weak.threshold * _UM:.1f} µm) "
        f"lie at a median reach of {weak.reach_weak:.3f} m (all: {weak.reach_all:.3f} m), z from "
        f"{z_weak[0]:.3f} to {z_weak[1]:.3f} m (all: {z_all[0]:.3f} to {z_all[1]:.3f} m, 5th to 95th percentile), "
        f"a median {weak.nearest_weak * _MM:.0f} mm from the nearest calibration pose "
        f"(all: {weak.nearest_all * _MM:.0f} mm).",
        f"Over the map, {_trend(weak.rho_reach, 'reach')}; "
        f"{_trend(weak.rho_nearest, 'the distance from the calibration poses')}.",
        "",
        "| configuration | joints / deg | position / m | u(x), u(y), u(z) / µm | u_pos / µm | reach / m "
        "| nearest pose / mm |",
        "|---|---|---|---|---|---|---|",
    ]
    for i in wmap.order[:worst]:
        joints = ", ".join(f"{v:.1f}" for v in np.degrees(wmap.configurations[i]))
        position = ", ".join(f"{v:.3f}" for v in wmap.positions[i])
        u = ", ".join(f"{v * _UM:.1f}" for v in wmap.standard_uncertainty[i])
        lines.append(
            f"| {int(i) + 1} | {joints} | {position} | {u} | {wmap.position_uncertainty[i] * _UM:.1f} | "
            f"{wmap.reach[i]:.3f} | {wmap.nearest_pose_distance[i] * _MM:.0f} |"
        )
    lines += ["", f"Table: `{files[0]}`; data: `{files[1]}`; plots: `{files[2]}`.", ""]
    lines += _field_lines(wmap)
    if wmap.warnings:
        lines += ["## Warnings", "", *(f"- {w}" for w in wmap.warnings), ""]
    return "\n".join(lines)


def write_map_report(
    workspace_map: WorkspaceMap,
    out_dir: str | Path,
    *,
    worst: int = 10,
    weakest_fraction: float = 0.1,
    stem: str = "map",
) -> MapReportFiles:
    """Write the map's table (CSV, JSON), summary plot (PNG) and Markdown note.

    Parameters
    ----------
    workspace_map : WorkspaceMap
    out_dir : str or Path
        Directory (created if needed).
    worst : int
        Weakest configurations listed in the Markdown table (>= 1).
    weakest_fraction : float
        Share of configurations the "weakest region" statistics describe, in (0, 1].
    stem : str
        File name stem: ``{stem}.csv``, ``{stem}.json``, ``{stem}.png``, ``{stem}.md``.

    Returns
    -------
    MapReportFiles
    """
    if isinstance(worst, bool) or not isinstance(worst, int) or worst < 1:
        msg = f"worst must be an integer >= 1, got {worst!r}"
        raise ConfigError(msg)
    weak = weakest_region(workspace_map, weakest_fraction)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = _write_csv(out / f"{stem}.csv", workspace_map)
    document = _write_json(out / f"{stem}.json", workspace_map, weak)
    figure = _plot(out / f"{stem}.png", workspace_map, weak)
    markdown = out / f"{stem}.md"
    markdown.write_text(
        _markdown(workspace_map, weak, (table.name, document.name, figure.name), worst), encoding="utf-8"
    )
    return MapReportFiles(table_csv=table, json=document, markdown=markdown, figure=figure)
