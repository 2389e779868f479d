"""The time loop of one case: turbulence -> pupil phase -> lucky-camera frames.

Per frame, the propagator samples every layer along each target's line of
sight at each of the frame's 2.5 ms steps (one call for all of them); the camera
image of each step's phase (scaled from 500 nm to the camera wavelength) is
added to the frame; the tilt-removed rms of the phases is the per-frame truth. A
frame is the mean of its steps' unit-flux images. With LGS, the frame's WFS
exposures are sensed after its steps.
"""

from dataclasses import dataclass

import numpy as np
import xarray as xr

from .atmosphere import Layer, R0Schedule
from .imaging import Camera, Imager
from .propagation import LineOfSight, Propagator, ScreenSet
from .progress import Progress
from .pupil import Telescope, TiltRemover
from .sensing import LgsSensing
from .tomography import lucky_frame_rms_nm
from .units import ARCSEC_RAD, REFERENCE_WAVELENGTH_M, phase_rad_to_nm


@dataclass(frozen=True)
class System:
    """The physical objects of one case, built from its resolved config."""

    telescope: Telescope
    camera: Camera
    layers: tuple[Layer, ...]
    r0: R0Schedule
    outer_scale_m: float
    targets: tuple[LineOfSight, ...]
    time_step_s: float
    steps_per_frame: int
    n_frames: int

    @classmethod
    def from_config(cls, case: dict) -> "System":
        atm, cam = case["atmosphere"], case["camera"]
        layers = tuple(Layer(*v) for v in zip(atm["height_m"], atm["cn2_fraction"],
                                              atm["wind_speed_m_s"], atm["wind_direction_deg"]))
        steps_per_frame = round(cam["frame_time_s"] / case["time_step_s"])
        return cls(
            telescope=Telescope(case["telescope"]["diameter_m"], case["telescope"]["obscuration_m"]),
            camera=Camera(cam["wavelength_m"], cam["n_pixels"], cam["field_of_view_arcsec"] / cam["n_pixels"]),
            layers=layers,
            r0=R0Schedule(atm["r0_500nm_m"], atm["r0_amplitude_m"], atm["r0_period_s"]),
            outer_scale_m=atm["outer_scale_m"],
            targets=tuple(LineOfSight(x * ARCSEC_RAD, y * ARCSEC_RAD) for x, y in case["targets_arcsec"]),
            time_step_s=case["time_step_s"],
            steps_per_frame=steps_per_frame,
            n_frames=int(np.floor(case["duration_s"] / cam["frame_time_s"] + 1e-9)),
        )

    def layer_scales(self, steps) -> np.ndarray:
        """Per-layer factors (k, n_layers) from the normalised screens to rad at
        500 nm at the k time ``steps``."""
        r0 = self.r0.r0_m(np.asarray(steps) * self.time_step_s).reshape(-1, 1)
        return r0 ** (-5 / 6) * np.sqrt([layer.cn2_fraction for layer in self.layers])


def simulate(system: System, screens: ScreenSet, write_frames, sensing: LgsSensing | None = None,
             block_frames: int = 32) -> xr.Dataset:
    """Run the case; ``write_frames(start, frames (target, k, n, n))`` receives the
    noiseless unit-flux frames. Returns the telemetry dataset. With ``sensing``,
    the LGS chain runs alongside and gives each frame's ``lgs_rms_nm``.

    Per frame it records the truth (tilt-removed rms) and the frame's value on
    the optical axis over the diffraction-limited peak, whose mean over frames
    is the long-exposure Strehl (no recentring): a plain mean, so its
    Monte-Carlo error follows from batch means.
    """
    imager = Imager(system.telescope, system.camera)
    mask = imager.mask
    propagator = Propagator(list(system.layers), screens, list(system.targets), imager.grid, mask=mask)
    tilt = TiltRemover.for_mask(imager.grid, mask)
    n_targets, n_frames, spf = len(system.targets), system.n_frames, system.steps_per_frame
    steps_max = propagator.n_steps_max if sensing is None else min(propagator.n_steps_max, sensing.n_steps_max)
    if n_frames * spf > steps_max:
        raise ValueError(f"the screens hold {steps_max} steps, the case needs {n_frames * spf}")
    to_camera = np.float32(REFERENCE_WAVELENGTH_M / system.camera.wavelength_m)
    n_pix = system.camera.n_pixels

    true_rms_nm = np.empty((n_targets, n_frames), dtype=np.float32)
    r0_frame = np.empty(n_frames)
    axis_strehl = np.empty((n_targets, n_frames), dtype=np.float32)
    lgs_rms = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    progress = Progress("frames", n_frames)
    buffer = np.empty((n_targets, block_frames, n_pix, n_pix), dtype=np.float32)
    intensity = np.empty((n_targets, imager.fft_size, imager.fft_size), dtype=np.float32)
    for start in range(0, n_frames, block_frames):
        count = min(block_frames, n_frames - start)
        for j in range(count):
            frame = start + j
            intensity.fill(0.0)
            rms2 = np.zeros(n_targets)
            steps = frame * spf + np.arange(spf)
            layer_scales = system.layer_scales(steps)
            for phase_500 in propagator.sample_valid(steps, layer_scales):  # (n_targets, n_valid) per step
                imager.accumulate(phase_500 * to_camera, intensity)
                rms2 += tilt.rms(phase_500) ** 2
            if sensing is not None:  # the frame's exposures (config: spf is a multiple of exposure_steps)
                slopes = [sensing.exposure_slopes(steps[i:i + sensing.exposure_steps],
                                                  layer_scales[i:i + sensing.exposure_steps])
                          for i in range(0, spf, sensing.exposure_steps)]
                lgs_rms[:, frame] = lucky_frame_rms_nm(sensing.rms_nm(np.stack(slopes)))
            buffer[:, j] = imager.to_pixels(intensity / spf)
            axis_strehl[:, frame] = buffer[:, j, n_pix // 2, n_pix // 2] / imager.diffraction_limited_peak
            true_rms_nm[:, frame] = phase_rad_to_nm(np.sqrt(rms2 / spf), REFERENCE_WAVELENGTH_M)
            r0_frame[frame] = np.mean(system.r0.r0_m((frame * spf + np.arange(spf)) * system.time_step_s))
        write_frames(start, buffer[:, :count])
        progress.update(start + count)

    frame_time = spf * system.time_step_s
    extra = {}
    if sensing is not None:
        extra["lgs_rms_nm"] = (("target", "frame"), lgs_rms, {
            "units": "nm", "long_name": "tilt-removed rms of the LGS tomographic reconstruction along the "
            "target, over the frame's WFS exposures"})
    return xr.Dataset(
        {
            **extra,
            "true_rms_nm": (("target", "frame"), true_rms_nm,
                            {"units": "nm", "long_name": "tilt-removed rms of the residual wavefront "
                             "over the pupil and the frame's exposure"}),
            "r0_500nm_m": (("frame",), r0_frame, {"units": "m", "long_name": "Fried parameter at 500 nm"}),
            "axis_strehl": (("target", "frame"), axis_strehl,
                            {"units": "1", "long_name": "frame value on the optical axis over the "
                             "diffraction-limited peak"}),
        },
        coords={
            "time_s": (("frame",), np.arange(n_frames) * frame_time,
                       {"units": "s", "long_name": "start time of the frame"}),
            "target_x_arcsec": (("target",), [t.theta_x_rad / ARCSEC_RAD for t in system.targets],
                                {"units": "arcsec", "long_name": "target x direction"}),
            "target_y_arcsec": (("target",), [t.theta_y_rad / ARCSEC_RAD for t in system.targets],
                                {"units": "arcsec", "long_name": "target y direction"}),
        },
        attrs={"diffraction_limited_peak": imager.diffraction_limited_peak,
               "pupil_samples": imager.grid.n_pix, "pupil_sample_m": imager.grid.dx_m},
    )
