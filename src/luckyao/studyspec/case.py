"""A case's validated config as typed, frozen objects: the one place dicts are unpacked.

Every physics object of a case (telescope, camera, layers, r0 in time, targets,
LGS, WFS, tomographic prior, AO settings) is built here from the resolved case
config (``studyspec.study.validate_study``); the rest of the package takes these
objects, never dicts.
"""

import functools
from dataclasses import dataclass

import numpy as np

from ..ao.apodisation import ApodisationSettings
from ..ao.dm import DeformableMirror
from ..atmosphere.intermittency import LayerVariability
from ..atmosphere.statistics import Layer, R0Schedule
from ..clock import FrameClock, frame_count, steps_per_frame
from ..geometry import LineOfSight
from ..optics.imaging import Camera
from ..optics.pupil import Telescope
from ..tomography.prior import TurbulencePrior
from ..units import ARCSEC_RAD
from ..wfs.beacons import LgsConfig
from ..wfs.calibration import BeaconSeeing
from ..wfs.geometric import noise_equivalent_angle_rad2
from ..wfs.shack_hartmann import ShackHartmann
from .schema import case_defaults


@dataclass(frozen=True)
class WfsSettings:
    """One LGS Shack-Hartmann per beacon: its geometry, exposure, detector noise, ``model``
    (``physical`` optics, or ``geometric``: :mod:`luckyao.wfs.geometric`) and, physical, its slope
    estimator (``centroider``, its ``threshold`` for ``tcog``, and ``calibration``: none,
    or ``dither`` for the calibrated response from ``calibration_draws`` turbulence draws,
    :mod:`luckyao.wfs.calibration`)."""

    n_subapertures: int
    n_pixels: int
    pixel_scale_arcsec: float
    exposure_steps: int
    min_illumination: float
    photons_per_subaperture: float | None
    read_noise_e: float
    centroider: str
    threshold: float
    calibration: str
    calibration_draws: int
    model: str

    @property
    def geometric(self) -> bool:
        return self.model == "geometric"

    def shack_hartmann(self, telescope: Telescope, lgs: LgsConfig) -> ShackHartmann:
        """The sensor of these settings at the beacons' wavelength."""
        return ShackHartmann(
            telescope,
            self.n_subapertures,
            lgs.wavelength_m,
            self.n_pixels,
            self.pixel_scale_arcsec,
            self.min_illumination,
            lgs.launch_diameter_m,
        )


@dataclass(frozen=True)
class TomographySettings:
    """MAP tomography: the layered prior, the slope-noise term, the point pitch, and the method
    (``dense`` slope-space matrices or the ``iterative`` layer-space estimate, solved to
    ``iterative_rtol``)."""

    prior: TurbulencePrior
    noise_rms_arcsec: float
    points_per_subaperture: int
    method: str
    iterative_rtol: float

    @property
    def iterative(self) -> bool:
        return self.method == "iterative"

    @property
    def noise_rms_rad(self) -> float:
        return self.noise_rms_arcsec * ARCSEC_RAD


@dataclass(frozen=True)
class AoSettings:
    """Open-loop AO: ``mode`` none / ltao / glao, the DM, the delay, what is corrected, whether
    the residual is budgeted and which laser-only criteria are recorded."""

    mode: str
    n_actuators: int
    coupling: float
    influence: str
    delay_steps: int
    correction_direction_arcsec: tuple[float, float]
    glao_max_height_m: float
    residual_budget: bool
    """Split the true residual along the first target into its parts (:mod:`luckyao.ao.budget`)."""
    laser_criteria: bool = False
    """Record the laser-only selection criteria (:mod:`luckyao.ao.laser_criteria`)."""
    apodisation: ApodisationSettings | None = None
    learned_training_seed: int | None = None
    """Seed of the training twin whose telemetry fits the ``learned`` criterion (:mod:`luckyao.steps.learned`)."""

    @property
    def enabled(self) -> bool:
        return self.mode != "none"

    @property
    def correction_direction_rad(self) -> tuple[float, float]:
        x, y = self.correction_direction_arcsec
        return x * ARCSEC_RAD, y * ARCSEC_RAD

    def deformable_mirror(self, telescope: Telescope) -> DeformableMirror:
        return DeformableMirror(telescope, self.n_actuators, self.coupling, self.influence)


def ao_from(block: dict) -> AoSettings:
    apodisation = block.get("apodisation")
    return AoSettings(
        **{
            **case_defaults("ao"),
            **block,
            "correction_direction_arcsec": tuple(block["correction_direction_arcsec"]),
            "apodisation": None if apodisation is None else ApodisationSettings(**apodisation),
        }
    )


def telescope_from(block: dict) -> Telescope:
    return Telescope(block["diameter_m"], block["obscuration_m"])


def lgs_from(block: dict) -> LgsConfig:
    """The asterism of an ``lgs`` block (``enabled`` is the case's business)."""
    return LgsConfig(**{k: v for k, v in block.items() if k != "enabled"})


def wfs_from(block: dict) -> WfsSettings:
    """The settings of a ``wfs`` block, its optional keys by default the schema's."""
    return WfsSettings(**{**case_defaults("wfs"), **block})


def slope_noise_covariance_rad2(
    settings: WfsSettings, wfs: ShackHartmann, lgs: LgsConfig, seeing: BeaconSeeing
) -> np.ndarray | None:
    """The LGS slopes' noise covariance (n_valid, 2, 2) [rad^2] that a geometric sensor with
    photon noise draws from and the tomography weighs its slopes by: each sub-aperture's NEA
    (:func:`luckyao.wfs.geometric.noise_equivalent_angle_rad2`); None otherwise (the tomography's
    ``noise_rms_arcsec``)."""
    if not settings.geometric or settings.photons_per_subaperture is None:
        return None
    return noise_equivalent_angle_rad2(wfs, lgs, seeing, settings.photons_per_subaperture, settings.read_noise_e)


def seeing_from(atmosphere: dict, lgs: LgsConfig) -> BeaconSeeing:
    """The turbulence the beacons see, for the mean r0 of an ``atmosphere`` block."""
    return BeaconSeeing(
        atmosphere["r0_500nm_m"],
        atmosphere["outer_scale_m"],
        tuple(atmosphere["height_m"]),
        tuple(atmosphere["cn2_fraction"]),
        lgs.height_m,
    )


def tomography_from(block: dict) -> TomographySettings:
    prior = TurbulencePrior(
        block["prior_r0_500nm_m"],
        block["prior_outer_scale_m"],
        tuple(block["layer_heights_m"]),
        tuple(block["layer_cn2_fraction"]),
    )
    options = {**case_defaults("tomography"), **block}
    return TomographySettings(
        prior,
        block["noise_rms_arcsec"],
        block["points_per_subaperture"],
        options["method"],
        options["iterative_rtol"],
    )


def targets_from(targets_arcsec) -> tuple[LineOfSight, ...]:
    return tuple(LineOfSight(x * ARCSEC_RAD, y * ARCSEC_RAD) for x, y in targets_arcsec)


@dataclass(frozen=True)
class Case:
    """The physical system and timing of one case."""

    telescope: Telescope
    camera: Camera
    layers: tuple[Layer, ...]
    r0: R0Schedule
    outer_scale_m: float
    targets: tuple[LineOfSight, ...]
    time_step_s: float
    steps_per_frame: int
    n_frames: int
    lgs: LgsConfig | None
    """The beacons, or None when the case has no LGS."""
    wfs: WfsSettings
    tomography: TomographySettings
    ao: AoSettings | None
    """None for an LGS chain alone (``studyspec.products.lgs_chain_config``: no targets either)."""
    seeing: BeaconSeeing | None = None
    """The turbulence as the beacons see it at the mean r0 (the seeing the WFS calibration assumes)."""
    layer_variability: LayerVariability | None = None
    """Each layer's strength in time (intermittent turbulence), or None: constant."""

    @classmethod
    def from_config(cls, case: dict) -> "Case":
        atm, cam = case["atmosphere"], case["camera"]
        layers = tuple(
            Layer(*v)
            for v in zip(atm["height_m"], atm["cn2_fraction"], atm["wind_speed_m_s"], atm["wind_direction_deg"])
        )
        return cls(
            telescope=telescope_from(case["telescope"]),
            camera=Camera(cam["wavelength_m"], cam["n_pixels"], cam["field_of_view_arcsec"] / cam["n_pixels"]),
            layers=layers,
            r0=R0Schedule(atm["r0_500nm_m"], atm["r0_amplitude_m"], atm["r0_period_s"]),
            outer_scale_m=atm["outer_scale_m"],
            targets=targets_from(case.get("targets_arcsec", ())),
            time_step_s=case["time_step_s"],
            steps_per_frame=steps_per_frame(case),
            n_frames=frame_count(case),
            lgs=lgs_from(case["lgs"]) if case["lgs"]["enabled"] else None,
            wfs=wfs_from(case["wfs"]),
            tomography=tomography_from(case["tomography"]),
            ao=ao_from(case["ao"]) if "ao" in case else None,
            seeing=seeing_from(atm, lgs_from(case["lgs"])) if case["lgs"]["enabled"] else None,
            layer_variability=LayerVariability(**atm["layer_variability"]) if "layer_variability" in atm else None,
        )

    def layer_scales(self, steps) -> np.ndarray:
        """Per-layer factors (k, n_layers) from the normalised screens to rad at
        500 nm at the k time ``steps``: ``r0(t)^-5/6 sqrt(Cn2 fraction)``, times
        ``sqrt(c_l(t))`` with layer variability (:attr:`cn2_factors`). Everything that
        samples the screens (science path, LGS sensor, residual budget) takes these."""
        r0 = self.r0.r0_m(np.asarray(steps) * self.time_step_s).reshape(-1, 1)
        scales = r0 ** (-5 / 6) * np.sqrt([layer.cn2_fraction for layer in self.layers])
        if self.layer_variability is None:
            return scales
        return scales * np.sqrt(self.cn2_factors[np.asarray(steps)])

    @functools.cached_property
    def cn2_factors(self) -> np.ndarray:
        """Each layer's Cn2 factor (n_steps, n_layers) at every time step of the case
        (:class:`luckyao.atmosphere.intermittency.LayerVariability`; the case must have it)."""
        return self.layer_variability.cn2_factors(len(self.layers), self.clock.n_steps, self.time_step_s)

    def r0_m(self, steps) -> np.ndarray:
        """r0 at 500 nm [m] of the whole profile at the time ``steps``: the sinusoid's, and with
        layer variability ``r0(t) (sum_l f_l c_l(t))^(-3/5)`` (``f_l`` the Cn2 fractions)."""
        r0 = self.r0.r0_m(np.asarray(steps) * self.time_step_s)
        if self.layer_variability is None:
            return r0
        fractions = np.array([layer.cn2_fraction for layer in self.layers])
        return r0 * (self.cn2_factors[np.asarray(steps)] @ fractions / fractions.sum()) ** (-3 / 5)

    def r0_samples_m(self) -> np.ndarray:
        """r0 at 500 nm [m] at every time step of the case (:meth:`r0_m`)."""
        return self.r0_m(np.arange(self.clock.n_steps))

    @property
    def clock(self) -> FrameClock:
        """The case's frames, time steps and WFS exposures (:mod:`luckyao.clock`)."""
        return FrameClock(self.steps_per_frame, self.wfs.exposure_steps, self.n_frames)

    def shack_hartmann(self) -> ShackHartmann:
        """The LGS WFS (the case must have LGS)."""
        return self.wfs.shack_hartmann(self.telescope, self.lgs)

    def slope_noise_covariance_rad2(self, wfs: ShackHartmann | None = None) -> np.ndarray | None:
        """The case's :func:`slope_noise_covariance_rad2` (of ``wfs``, by default :meth:`shack_hartmann`'s)."""
        wfs = self.shack_hartmann() if wfs is None else wfs
        return slope_noise_covariance_rad2(self.wfs, wfs, self.lgs, self.seeing)
