"""Geometric propagation: frozen flow, cone effect and interpolation against geometry."""

import numpy as np
import pytest

from luckyao.atmosphere.screens import ScreenSet, strip_screen, strip_spec
from luckyao.atmosphere.statistics import Layer
from luckyao.geometry import LineOfSight, footprint_m
from luckyao.optics.propagation import Propagator
from luckyao.optics.pupil import PupilGrid

DT_S = 0.0025
GRID = PupilGrid(24, 4.2 / 24)


def _single_layer(height_m, speed, direction_deg, n_steps=200, radius_m=4.0, seed=3):
    layer = Layer(height_m, 1.0, speed, direction_deg)
    spec = strip_spec(layer, DT_S, n_steps, 0.03, radius_m, 30.0, 12.0)
    screen = strip_screen(spec, 20.0, np.random.default_rng(seed))
    return layer, ScreenSet.from_screens([spec], [screen]), screen


def _annulus(grid):
    r = np.hypot(*grid.xy_m)
    return (r < 2.1) & (r > 0.6)


@pytest.mark.parametrize("grid", [GRID, PupilGrid(23, 4.2 / 23)], ids=["even", "odd"])
def test_plane_screen_is_sampled_exactly_on_and_off_axis_with_cone_and_wind(grid):
    """A screen linear in position is reproduced exactly by bilinear interpolation,
    so this checks every geometric step: the skewed strip's line offsets and
    major axis, origin, sample spacing, frozen-flow shift, cone scaling,
    off-axis and grid offsets, for winds closer to x and to y; lines go in
    pairs, so an odd grid too."""
    a, b = 0.7, -1.3  # rad per m along sky x and y
    annulus = _annulus(grid)
    for direction in (57.0, 160.0, 231.0, -20.0):
        layer, screens, _ = _single_layer(5000.0, 13.0, direction, n_steps=3000)  # 98 m of flow
        spec = screens.specs[0]
        i, j = np.meshgrid(np.arange(spec.n_major), np.arange(spec.n_minor), indexing="ij")
        major = spec.origin_m[0] + i * spec.dx_m
        minor = spec.origin_m[1] + (j + spec.line_offset(i)) * spec.dx_m
        sky_x, sky_y = (major, minor) if spec.major_axis == 0 else (minor, major)
        plane = ScreenSet.from_screens([spec], [(a * sky_x + b * sky_y).astype(np.float32)])
        lgs = LineOfSight(2e-5, -4e-5, 22000.0)
        star = LineOfSight(-1e-4, 5e-5)
        centre = (0.3, -0.2)
        prop = Propagator([layer], plane, [star, lgs], grid, centre_xy_m=centre)
        x, y = grid.xy_m
        e = layer.wind_unit
        masked = Propagator([layer], plane, [star, lgs], grid, centre_xy_m=centre, mask=annulus)
        for step in (0, 13, 2999):
            phase = prop.sample([step], [[1.0]])[0]
            for d, los in enumerate((star, lgs)):
                fx, fy = footprint_m(x + centre[0], y + centre[1], layer.height_m, los)
                qx, qy = fx - e[0] * 13.0 * DT_S * step, fy - e[1] * 13.0 * DT_S * step
                np.testing.assert_allclose(phase[d], a * qx + b * qy, atol=2e-3)
            # a mask computes only its samples, zero elsewhere; sample_valid packs them in mask order
            np.testing.assert_array_equal(masked.sample([step], [[1.0]])[0], np.where(annulus, phase, 0.0))
            np.testing.assert_array_equal(masked.sample_valid([step], [[1.0]])[0], phase[:, annulus])


def test_frozen_flow_moves_the_screen_by_the_wind_vector():
    """The on-axis phase at step n equals the phase seen at step 0 through a line
    of sight displaced by -v n dt at the layer: the turbulence moved by v n dt."""
    height, speed, direction = 1000.0, 10.0, 30.0
    layer, screens, _ = _single_layer(height, speed, direction)
    n = 7  # 0.175 m: not a whole number of pupil samples
    shift = speed * n * DT_S * np.array([np.cos(np.radians(direction)), np.sin(np.radians(direction))])
    displaced = LineOfSight(-shift[0] / height, -shift[1] / height)
    prop = Propagator([layer], screens, [LineOfSight(0.0, 0.0), displaced], GRID)
    moved = prop.sample([n], [[1.0]])[0][0]
    reference = prop.sample([0], [[1.0]])[0][1]
    np.testing.assert_allclose(moved, reference, atol=1e-4)
    assert np.std(moved - prop.sample([0], [[1.0]])[0][0]) > 0.1  # the screen did move


def test_cone_effect_scales_the_footprint():
    layer, screens, _ = _single_layer(9000.0, 20.0, 200.0)
    beacon_height = 22000.0
    scale = 1 - 9000.0 / beacon_height
    lgs = Propagator([layer], screens, [LineOfSight(0.0, 0.0, beacon_height)], GRID)
    star = Propagator([layer], screens, [LineOfSight(0.0, 0.0)], PupilGrid(GRID.n_pix, scale * GRID.dx_m))
    np.testing.assert_allclose(lgs.sample([5], [[1.0]])[0], star.sample([5], [[1.0]])[0], atol=1e-5)


def test_layers_add_with_their_weights():
    l1, s1, screen1 = _single_layer(100.0, 5.0, 0.0, seed=1)
    l2, s2, screen2 = _single_layer(8000.0, 30.0, 250.0, seed=2)
    los = [LineOfSight(1e-5, 0.0)]
    both = Propagator([l1, l2], ScreenSet.from_screens(s1.specs + s2.specs, [screen1, screen2]), los, GRID)
    one = Propagator([l1], s1, los, GRID)
    two = Propagator([l2], s2, los, GRID)
    np.testing.assert_allclose(
        both.sample([9], [[0.5, 2.0]])[0],
        0.5 * one.sample([9], [[1.0]])[0] + 2.0 * two.sample([9], [[1.0]])[0],
        atol=1e-4,
    )


def test_steps_sampled_together_equal_steps_sampled_one_by_one():
    """A frame's steps go in one call (with each step's layer weights): the same
    numbers as one call per step, for layers along x and y and a masked grid."""
    l1, s1, screen1 = _single_layer(100.0, 5.0, 10.0, seed=1)
    l2, s2, screen2 = _single_layer(8000.0, 30.0, 250.0, seed=2)
    screens = ScreenSet.from_screens(s1.specs + s2.specs, [screen1, screen2])
    assert {spec.major_axis for spec in screens.specs} == {0, 1}
    prop = Propagator(
        [l1, l2], screens, [LineOfSight(1e-5, 0.0), LineOfSight(0.0, 2e-5, 22000.0)], GRID, mask=_annulus(GRID)
    )
    steps, scales = [3, 4, 11], [[1.0, 2.0], [0.5, 1.5], [3.0, 0.2]]
    together = prop.sample_valid(steps, scales)
    for step, scale, phase in zip(steps, scales, together):
        np.testing.assert_array_equal(phase, prop.sample_valid([step], [scale])[0])


def test_leaving_the_screen_is_an_error():
    layer, screens, _ = _single_layer(1000.0, 10.0, 0.0, n_steps=50)
    prop = Propagator([layer], screens, [LineOfSight(0.0, 0.0)], GRID)
    with pytest.raises(IndexError):
        prop.sample([prop.n_steps_max], [[1.0]])[0]
    with pytest.raises(ValueError, match="leaves its screen"):
        Propagator([layer], screens, [LineOfSight(0.0, 0.01)], GRID)  # 10 m across the wind


def test_uplink_line_of_sight_follows_the_beam_from_an_offset_launch():
    """The uplink cone, anchored on an off-axis launch point, against the ray
    geometry of ``lgs.cone_coordinates``."""
    from luckyao.geometry import cone_coordinates, uplink_line_of_sight

    launch, direction, beacon_height = np.array([0.4, -0.3]), (5e-5, -1e-4), 22000.0
    x, y = GRID.xy_m
    for height in (0.0, 4500.0, 18000.0):
        expected = cone_coordinates(x + launch[0], y + launch[1], height, beacon_height, direction, origin_xy_m=launch)
        got = footprint_m(x + launch[0], y + launch[1], height, uplink_line_of_sight(direction, launch, beacon_height))
        np.testing.assert_allclose(got, expected, atol=1e-12)
