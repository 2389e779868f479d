"""LGS geometry: asterism, cone footprints, elongation."""

import numpy as np

from luckyao.geometry import cone_coordinates, footprint_scale
from luckyao.units import ARCSEC_RAD
from luckyao.wfs.beacons import LgsConfig, altitude_profile, elongation_offsets_rad

from reference import elongation_length_rad


def test_asterism_is_a_40_arcsec_circle():
    directions = LgsConfig.rayleigh().directions_rad / ARCSEC_RAD
    np.testing.assert_allclose(np.hypot(*directions.T), 20.0)
    np.testing.assert_allclose(directions.sum(axis=0), 0.0, atol=1e-12)


def test_cone_footprint_matches_ray_geometry():
    """Rays from pupil points to a beacon at (theta H, H) cross height h at the
    point found by intersecting the 3-D straight line: footprint diameter
    D (1 - h/H), centre theta h."""
    config = LgsConfig.rayleigh()
    theta = config.directions_rad[1]
    beacon = np.array([theta[0] * config.height_m, theta[1] * config.height_m, config.height_m])
    angle = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    edge = 2.1 * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], -1)
    for height in (47.0, 4500.0, 18000.0):
        t = height / config.height_m  # fraction of the way up each ray
        crossing = edge + t * (beacon - edge)
        x_l, y_l = cone_coordinates(edge[:, 0], edge[:, 1], height, config.height_m, theta)
        np.testing.assert_allclose(x_l, crossing[:, 0], atol=1e-9)
        np.testing.assert_allclose(y_l, crossing[:, 1], atol=1e-9)
        centre = np.array([x_l.mean(), y_l.mean()])
        np.testing.assert_allclose(centre, theta * height, atol=1e-9)
        diameter = 2 * np.hypot(x_l - centre[0], y_l - centre[1])
        np.testing.assert_allclose(diameter, 4.2 * (1 - height / config.height_m))
        np.testing.assert_allclose(footprint_scale(height, config.height_m), diameter / 4.2)
    # a star (H = inf) keeps the full pupil, shifted by theta h
    x_l, _ = cone_coordinates(edge[:, 0], edge[:, 1], 9000.0, np.inf, theta)
    np.testing.assert_allclose(x_l, edge[:, 0] + theta[0] * 9000.0)


def test_range_gate_elongation_length_and_direction():
    """Extent of the gate [H - dH/2, H + dH/2] seen from baseline b is
    b (1/(H - dH/2) - 1/(H + dH/2)) ~ b dH / H^2, along launch -> sub-aperture."""
    config = LgsConfig.rayleigh()
    z_m, weights = altitude_profile(config, 200)
    np.testing.assert_allclose(weights.sum(), 1.0)
    subapertures = np.array([[2.0, 0.0], [0.0, -1.0], [1.2, 1.2]])
    offsets = elongation_offsets_rad(subapertures, config.launch_xy_m, config.height_m, z_m)
    for k, p in enumerate(subapertures):
        b = np.hypot(*p)
        extent = np.hypot(*(offsets[k, -1] - offsets[k, 0]))
        h, dh = config.height_m, config.profile_width_m
        sample_width = dh / 200  # profile samples are slice mid-points
        exact = b * (1 / (h - dh / 2 + sample_width / 2) - 1 / (h + dh / 2 - sample_width / 2))
        np.testing.assert_allclose(extent, exact, rtol=1e-9)
        np.testing.assert_allclose(extent, elongation_length_rad(b, dh, h), rtol=0.01)
        direction = (offsets[k, -1] - offsets[k, 0]) / extent
        np.testing.assert_allclose(direction, p / b, atol=1e-12)  # higher = further out
    # 1.34" for the outermost sub-aperture of the Rayleigh system (b = 2.1 m)
    np.testing.assert_allclose(elongation_length_rad(2.1, 1500, 22e3) / ARCSEC_RAD, 1.342, rtol=1e-3)


def test_sodium_profile_is_gaussian_with_configured_fwhm():
    config = LgsConfig.sodium()
    z_m, weights = altitude_profile(config, 601)
    mean = weights @ z_m
    sigma = np.sqrt(weights @ (z_m - mean) ** 2)
    np.testing.assert_allclose(mean, 90e3, rtol=1e-9)
    # truncated at +-1.5 FWHM = +-3.53 sigma: variance reduced by < 0.5%
    np.testing.assert_allclose(sigma * 2 * np.sqrt(2 * np.log(2)), 10e3, rtol=0.005)


def test_off_axis_launch_shifts_the_elongation_origin():
    config = LgsConfig.rayleigh(launch_x_m=2.0)
    z_m, _ = altitude_profile(config, 3)
    offsets = elongation_offsets_rad(np.array([[2.0, 0.0]]), config.launch_xy_m, config.height_m, z_m)
    np.testing.assert_allclose(offsets, 0.0)  # sub-aperture at the launch sees a point
