"""Lines of sight through a layered atmosphere: directions, the cone effect, footprints.

All lengths in metres, angles in radians (small-angle vectors ``(theta_x,
theta_y)``). A ray from pupil point ``p`` [m] towards ``theta`` from a source at
height ``H`` crosses the layer at height ``h`` at ``p (1 - h/H) + theta h``
(cone effect, focal anisoplanatism: Tallon & Foy 1990, A&A 235, 549;
``H = inf`` for a star). The one home of that formula is :func:`footprint_scale`.
"""

from dataclasses import dataclass

import numpy as np

from .units import ARCSEC_RAD


@dataclass(frozen=True)
class LineOfSight:
    """Direction ``(theta_x, theta_y)`` [rad] to a source at ``height_m`` (inf: a star)."""

    theta_x_rad: float
    theta_y_rad: float
    height_m: float = np.inf


def footprint_m(points_x_m, points_y_m, layer_height_m, los: LineOfSight):
    """Positions (x, y) [m] where rays from pupil points towards ``los`` cross a layer."""
    return cone_coordinates(points_x_m, points_y_m, layer_height_m, los.height_m, (los.theta_x_rad, los.theta_y_rad))


def asterism_directions_rad(n_beacons: int, diameter_arcsec: float, rotation_deg: float = 0.0) -> np.ndarray:
    """Directions (n, 2) [rad] evenly spaced on a circle of ``diameter_arcsec``.

    Beacon ``k`` is at azimuth ``rotation + 2 pi k / n`` (counted from +x
    towards +y). A single beacon with diameter 0 is on axis.
    """
    radius_rad = 0.5 * diameter_arcsec * ARCSEC_RAD
    azimuth = np.deg2rad(rotation_deg) + 2 * np.pi * np.arange(n_beacons) / n_beacons
    return radius_rad * np.stack([np.cos(azimuth), np.sin(azimuth)], axis=-1)


def footprint_scale(layer_height_m, beacon_height_m):
    """Cone compression ``1 - h/H`` of the pupil footprint at height ``h``.

    ``beacon_height_m = inf`` (a star) gives 1 (Tallon & Foy 1990).
    """
    return 1.0 - np.asarray(layer_height_m, dtype=float) / beacon_height_m


def cone_coordinates(x_m, y_m, layer_height_m: float, beacon_height_m: float, direction_rad, origin_xy_m=(0.0, 0.0)):
    """Where rays from pupil points ``(x, y)`` [m] to a beacon cross a layer.

    Returns ``(x_l, y_l)`` [m] in layer coordinates (same axes as the pupil):
    ``p_l = o + (p - o) (1 - h/H) + theta h`` where ``o`` is the point the
    cone is anchored on (the beam converges from pupil points to the beacon):
    the telescope axis for the downlink, the launch position for the uplink
    beam. Arrays broadcast; inputs are not modified.
    """
    scale = footprint_scale(layer_height_m, beacon_height_m)
    ox, oy = origin_xy_m
    theta_x, theta_y = direction_rad
    x_l = ox + (np.asarray(x_m) - ox) * scale + theta_x * layer_height_m
    y_l = oy + (np.asarray(y_m) - oy) * scale + theta_y * layer_height_m
    return x_l, y_l


def uplink_line_of_sight(direction_rad, launch_xy_m, height_m: float) -> LineOfSight:
    """The line of sight whose cone through points ``p`` of the launch aperture is
    the uplink beam's: anchored on the launch point ``o``, the beam crosses height
    ``h`` at ``o + (p - o) s + theta h = s p + (theta + o / H) h`` (s = 1 - h/H)."""
    return LineOfSight(
        direction_rad[0] + launch_xy_m[0] / height_m, direction_rad[1] + launch_xy_m[1] / height_m, height_m
    )


def footprint_centre_m(los: LineOfSight, layer_height_m: float) -> tuple[float, float]:
    """Centre (x, y) [m] of the pupil's footprint on a layer along ``los``."""
    return los.theta_x_rad * layer_height_m, los.theta_y_rad * layer_height_m


def footprint_coverage(
    diameter_m: float, target: LineOfSight, beacons: list[LineOfSight], layer_height_m: float, n_samples: int = 201
) -> float:
    """Fraction of the target's pupil footprint on a layer that at least one beacon's
    footprint covers (discs of diameter ``D (1 - h/H)``, on ``n_samples`` squared points)."""
    grid = np.linspace(-diameter_m / 2, diameter_m / 2, n_samples)
    gx, gy = np.meshgrid(grid, grid)
    inside = np.hypot(gx, gy) <= diameter_m / 2
    px, py = footprint_m(gx, gy, layer_height_m, target)
    covered = np.zeros_like(inside)
    for beacon in beacons:
        cx, cy = footprint_centre_m(beacon, layer_height_m)
        radius = diameter_m * footprint_scale(layer_height_m, beacon.height_m) / 2
        covered |= np.hypot(px - cx, py - cy) <= radius
    return float(covered[inside].mean())
