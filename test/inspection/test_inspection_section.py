"""Section algorithms against analytic truths (no noise)."""

from __future__ import annotations

import numpy as np
import pytest
from inspection_data import CASCADE, ellipse, stadium
from scipy.spatial import Voronoi, cKDTree

from robocal_uncertainty.core.instruments.cmm import CmmInstrument, point_displacements, point_error_sources
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import NominalSection, read_cascade_profile
from robocal_uncertainty.inspection.registration import polygon_centroid, register_to_nominal, rotation
from robocal_uncertainty.inspection.section import (
    PARAMETER_NAMES,
    SectionOptions,
    SectionParameters,
    chord_length,
    evaluate_section,
    max_thickness,
    order_along_contour,
    point_to_polyline,
    profile_deviations,
)
from robocal_uncertainty.inspection.segmentation import (
    LEADING_EDGE,
    PRESSURE_SIDE,
    SUCTION_SIDE,
    TRAILING_EDGE,
    farthest_pair,
    fit_circle,
    segment_section,
)
from robocal_uncertainty.inspection.simulate import simulate_section_scan

NM = 1e-9  # [m]


def moved(points: np.ndarray, offset: tuple[float, float], twist: float, pivot: np.ndarray) -> np.ndarray:
    return (points - pivot) @ rotation(twist).T + pivot + np.asarray(offset)


def test_fit_circle_recovers_centre_and_radius() -> None:
    t = np.linspace(0.3, 1.9, 9)
    points = np.column_stack([1e-3 + 2e-3 * np.cos(t), -4e-3 + 2e-3 * np.sin(t)])
    circle = fit_circle(points)
    assert circle.centre == pytest.approx((1e-3, -4e-3), abs=1e-15)
    assert circle.radius == pytest.approx(2e-3, abs=1e-15)
    assert circle.radius_error < 1e-15


def test_fit_circle_refuses_collinear_and_too_few_points() -> None:
    with pytest.raises(InputError, match="at least 3 points"):
        fit_circle(np.zeros((2, 2)))
    with pytest.raises(InputError, match="collinear"):
        fit_circle(np.column_stack([np.arange(5.0), np.zeros(5)]))


def test_farthest_pair_of_an_ellipse_is_its_major_axis() -> None:
    points = ellipse(30e-3, 5e-3, 400)
    assert farthest_pair(points) == (0, 200)


def test_stadium_parameters_are_exact() -> None:
    radius, length = 5e-3, 50e-3
    points = stadium(radius, length, 40, 100)
    curve = NominalCurve(NominalSection(points, "stadium"))
    # A tolerance far below the first straight point's departure from the circle (1 µm) stops
    # the edge growth exactly where the semicircles end.
    result = evaluate_section(points, curve, SectionOptions(edge_tolerance=1e-9))
    p = result.parameters
    assert p.max_thickness == pytest.approx(2 * radius, abs=0.01e-6)
    assert p.chord_length == pytest.approx(length + 2 * radius, abs=0.01e-6)
    assert abs(p.axial_offset) < NM and abs(p.circumferential_offset) < NM
    assert abs(p.twist_angle) < np.deg2rad(1e-6)
    assert max(p.profile_leading_edge, p.profile_trailing_edge) < 0.01e-6
    assert max(p.profile_pressure_side, p.profile_suction_side) < 0.01e-6
    seg = result.segmentation
    # The edge circles are the stadium's semicircles; the straight sides stop their growth.
    for circle, centre in ((seg.leading_edge_circle, (0.0, 0.0)), (seg.trailing_edge_circle, (length, 0.0))):
        assert circle.radius == pytest.approx(radius, abs=1e-12)
        assert circle.centre == pytest.approx(centre, abs=1e-12)
    le = result.points[seg.labels == LEADING_EDGE]
    assert (le[:, 0] <= 1e-12).all() and le.shape[0] > 40
    assert (result.points[seg.labels == TRAILING_EDGE][:, 0] >= length - 1e-12).all()
    # Uncambered: the suction side is left of the leading-to-trailing-edge line (y > 0).
    assert (result.points[seg.labels == SUCTION_SIDE][:, 1] > 0).all()
    assert (result.points[seg.labels == PRESSURE_SIDE][:, 1] < 0).all()


@pytest.mark.parametrize(("offset", "twist_deg"), [((0.1e-3, -0.05e-3), 0.05), ((-1.5e-3, 0.8e-3), -2.0)])
def test_rigid_copies_give_the_applied_offsets_and_twist(offset: tuple[float, float], twist_deg: float) -> None:
    points = stadium(5e-3, 50e-3, 40, 100)
    curve = NominalCurve(NominalSection(points, "stadium"))
    pivot = polygon_centroid(points)
    copy = moved(points, offset, np.deg2rad(twist_deg), pivot)
    p = evaluate_section(copy, curve).parameters
    assert p.axial_offset == pytest.approx(offset[0], abs=NM)
    assert p.circumferential_offset == pytest.approx(offset[1], abs=NM)
    assert p.twist_angle == pytest.approx(np.deg2rad(twist_deg), abs=1e-9)
    assert p.max_thickness == pytest.approx(10e-3, abs=0.01e-6)
    assert p.chord_length == pytest.approx(60e-3, abs=0.01e-6)
    assert max(p.as_array()[5:]) < 0.01e-6


def test_rigid_copy_of_the_real_blade(rotor37_curve: NominalCurve) -> None:
    points = rotor37_curve.section.points
    twist = np.deg2rad(0.0512)
    copy = moved(points, (-0.1013e-3, 0.0538e-3), twist, polygon_centroid(points))
    reg = register_to_nominal(copy, rotor37_curve)
    assert reg.offset == pytest.approx([-0.1013e-3, 0.0538e-3], abs=NM)
    assert reg.twist == pytest.approx(twist, abs=1e-9)
    assert reg.rms < NM


@pytest.mark.parametrize(("offset", "twist_deg"), [((0.0, 1e-3), 0.3), ((1e-3, 0.0), 0.5), ((1e-3, -1e-3), -2.0)])
def test_large_moves_of_the_real_blade_register_exactly(
    rotor37_curve: NominalCurve, offset: tuple[float, float], twist_deg: float
) -> None:
    # A 300 mm blade moved by up to 1 mm and 2 degrees: the registration used to settle on a
    # wrong local minimum (10-100 µm off, RMS below the mismatch limit) or refuse the cloud.
    cloud = simulate_section_scan(rotor37_curve, 1836, offset=offset, twist=np.deg2rad(twist_deg))
    reg = register_to_nominal(cloud.xy[::-1], rotor37_curve)
    assert reg.offset == pytest.approx(offset, abs=NM)
    assert reg.twist == pytest.approx(np.deg2rad(twist_deg), abs=1e-9)
    assert reg.rms < NM


def test_twist_about_a_stated_pivot() -> None:
    points = stadium(5e-3, 50e-3, 40, 100)
    curve = NominalCurve(NominalSection(points, "stadium"))
    pivot = np.array([0.0, 0.0])  # the leading-edge circle centre
    copy = moved(points, (0.0, 0.0), 0.01, pivot)
    reg = register_to_nominal(copy, curve, pivot=pivot)
    assert reg.offset == pytest.approx([0.0, 0.0], abs=NM)
    assert reg.twist == pytest.approx(0.01, abs=1e-12)


def test_ellipse_thickness_and_chord() -> None:
    a, b = 30e-3, 4e-3
    points = ellipse(a, b, 800)
    curve = NominalCurve(NominalSection(points, "ellipse"))
    p = evaluate_section(points, curve).parameters
    assert p.max_thickness == pytest.approx(2 * b, abs=0.01e-6)
    assert p.chord_length == pytest.approx(2 * a, abs=0.01e-6)


def test_max_thickness_is_the_inscribed_circle_of_a_lens() -> None:
    # Lens of two circular arcs (radius R, half-thickness t): largest inscribed circle 2t.
    big, half = 50e-3, 3e-3
    s = np.linspace(-0.95, 0.95, 401) * np.sqrt(big**2 - (big - half) ** 2)
    upper = np.column_stack([s, np.sqrt(big**2 - s**2) - (big - half)])
    lower = upper * [1.0, -1.0]
    thickness = max_thickness(lower, upper)
    # The suction-side polyline's chords pass 2 nm inside the arc next to the vertex.
    assert thickness.value == pytest.approx(2 * half, abs=0.01e-6)
    assert lower[thickness.pressure_point, 0] == pytest.approx(0.0, abs=1e-15)


def test_point_to_polyline_distances() -> None:
    line = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    d, seg, interior = point_to_polyline(np.array([[0.5, -2.0], [2.0, 0.5], [-1.0, 0.0]]), line)
    assert d == pytest.approx([2.0, 1.0, 1.0])
    assert seg.tolist() == [0, 1, 0]
    assert interior.tolist() == [True, True, False]


def test_profile_of_a_known_form_error(stadium_curve: NominalCurve) -> None:
    amplitude = 3e-6
    cloud = simulate_section_scan(stadium_curve, 1200, form_amplitude=amplitude, form_waves=40)
    p = evaluate_section(cloud, stadium_curve).parameters
    # 40 waves around a 131 mm contour: every side holds crests and troughs, so max - min is 2a
    # up to the small rigid motion the registration takes out of the unbalanced waves.
    assert p.profile_pressure_side == pytest.approx(2 * amplitude, rel=0.05)
    assert p.profile_suction_side == pytest.approx(2 * amplitude, rel=0.05)


def test_simulated_scan_of_the_real_blade_recovers_the_truth(rotor37_curve: NominalCurve) -> None:
    twist = np.deg2rad(0.0512)
    cloud = simulate_section_scan(rotor37_curve, 1836, offset=(-0.1013e-3, 0.0538e-3), twist=twist)
    result = evaluate_section(cloud, rotor37_curve)
    p = result.parameters
    assert p.axial_offset == pytest.approx(-0.1013e-3, abs=NM)
    assert p.circumferential_offset == pytest.approx(0.0538e-3, abs=NM)
    assert p.twist_angle == pytest.approx(twist, abs=1e-9)
    assert p.max_thickness == pytest.approx(30.37e-3, abs=0.01e-3)
    assert max(p.as_array()[5:]) < 0.05e-6  # spline interpolation between the nominal points
    counts = np.bincount(result.segmentation.labels, minlength=4)
    assert counts.sum() == 1836 and (counts[:2] >= 10).all()


def test_parameters_round_trip_through_arrays() -> None:
    values = np.arange(1.0, 10.0)
    params = SectionParameters.from_array(values)
    assert params.as_array().tolist() == values.tolist()
    assert len(PARAMETER_NAMES) == 9 and PARAMETER_NAMES[4] == "twist_angle"
    with pytest.raises(InputError, match=r"shape \(9,\)"):
        SectionParameters.from_array(values[:3])


def test_profile_deviations_per_region() -> None:
    residual = np.array([1.0, 3.0, -1.0, 2.0, 5.0, 4.0, 0.0, 0.0])
    labels = np.array([0, 0, 1, 1, 2, 2, 3, 3])
    assert profile_deviations(residual, labels).tolist() == [2.0, 3.0, 1.0, 0.0]
    with pytest.raises(InputError, match="suction_side has no points"):
        profile_deviations(residual[:6], labels[:6])


@pytest.mark.parametrize("factor", [1e3, 1e-3, 25.4, 0.1])
def test_a_cloud_in_another_unit_is_refused_with_its_size(rotor37_curve: NominalCurve, factor: float) -> None:
    cloud = simulate_section_scan(rotor37_curve, 400).xy * factor
    with pytest.raises(InputError, match=r"span .* mm but the nominal section .* mm: a different length unit"):
        evaluate_section(cloud, rotor37_curve)


def test_careless_input_is_refused(stadium_curve: NominalCurve) -> None:
    points = stadium(5e-3, 50e-3, 40, 100)
    with pytest.raises(InputError, match="at least 20 points"):
        evaluate_section(points[:10], stadium_curve)
    bad = points.copy()
    bad[7, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        evaluate_section(bad, stadium_curve)
    with pytest.raises(InputError, match=r"shape \(n, 2\)"):
        evaluate_section(np.zeros((30, 3)), stadium_curve)
    # Half a section: open.
    with pytest.raises(InputError, match="open"):
        evaluate_section(points[points[:, 1] > 0], stadium_curve)
    # A different section: registration cannot bring it onto the nominal.
    with pytest.raises(InputError, match="do not match the nominal"):
        evaluate_section(ellipse(30e-3, 4e-3, 400), stadium_curve)
    with pytest.raises(InputError, match="open"):
        order_along_contour(np.array([0.0, 0.1, 0.2]), 10.0)
    with pytest.raises(InputError, match="edge_tolerance"):
        segment_section(points, edge_tolerance=0.0)
    with pytest.raises(InputError, match="at least 20 points"):
        segment_section(points[:5])


def test_chord_length_is_the_farthest_pair_distance() -> None:
    chord, i, j = chord_length(ellipse(30e-3, 5e-3, 400))
    assert chord == pytest.approx(60e-3, abs=1e-15)
    assert (i, j) == (0, 200)


@pytest.mark.parametrize("blade", ["rotor37", "cascade"])
def test_real_blades_with_simulated_cmm_noise(blade: str, rotor37_curve: NominalCurve) -> None:
    # Cascade scaled to a 600 mm chord: maximum thickness 30 mm like the seed's blade.
    curve = rotor37_curve if blade == "rotor37" else NominalCurve(read_cascade_profile(CASCADE, chord_m=0.6))
    twist = np.deg2rad(0.0512)
    cloud = simulate_section_scan(curve, 1836, offset=(-0.1013e-3, 0.0538e-3), twist=twist, form_amplitude=5e-6)
    clean = evaluate_section(cloud, curve)
    sources = point_error_sources(CmmInstrument(), clean.points, clean.registration.normal, reference=clean.points[0])
    noisy = clean.points + point_displacements(sources, np.random.default_rng(9))[0]
    result = evaluate_section(noisy, curve)
    truth, measured = clean.parameters.as_array(), result.parameters.as_array()
    # Errors of a few µm per point: offsets within 1 µm, twist within 1e-5 rad, thickness and
    # chord within 10 µm, profiles within 15 µm of the noise-free evaluation.
    assert measured[2:4] == pytest.approx(truth[2:4], abs=1e-6)
    assert measured[4] == pytest.approx(truth[4], abs=1e-5)
    assert measured[:2] == pytest.approx(truth[:2], abs=10e-6)
    assert measured[5:] == pytest.approx(truth[5:], abs=15e-6)
    assert np.array_equal(np.bincount(result.segmentation.labels, minlength=4) > 0, [True] * 4)


def test_max_thickness_is_the_largest_inscribed_circle_of_the_real_blade(rotor37_curve: NominalCurve) -> None:
    # Largest inscribed circle of the nominal curve: the Voronoi vertex of 20 000 curve points
    # farthest from its sites among those inside the section.
    dense = rotor37_curve.point(np.linspace(0.0, rotor37_curve.period, 20_000, endpoint=False))
    vertices = Voronoi(dense).vertices
    vertices = vertices[np.abs(vertices - dense.mean(axis=0)).max(axis=1) < 0.3]
    inside = vertices[rotor37_curve.closest(vertices).distance < 0]
    diameter = 2.0 * float(cKDTree(dense).query(inside)[0].max())
    cloud = simulate_section_scan(rotor37_curve, 1836)
    thickness = evaluate_section(cloud, rotor37_curve).parameters.max_thickness
    # The seed's algorithm on 1 836 points is within 0.1 µm of the inscribed-circle diameter.
    assert thickness == pytest.approx(diameter, abs=0.1e-6)
    assert diameter == pytest.approx(30.367e-3, abs=1e-6)
