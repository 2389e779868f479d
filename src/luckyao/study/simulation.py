"""The time loop of one case, as two chains per lucky frame:

* LGS sensor -> estimator (-> correction): the frame's WFS exposures give slopes
  (open loop: they never see the DM, so they run before the science steps they
  correct); the estimator gives each target's ``lgs_rms``, and with AO each
  exposure's DM command (applied with the configured delay) and the
  pseudo-closed-loop ``lgs_residual_rms``;
* phase source -> correction -> imager and truth: the propagator samples every
  layer along each target's line of sight at each of the frame's 2.5 ms steps
  (one call for all of them); the DM surface of the step is subtracted; the
  camera image of each step's residual phase (scaled from 500 nm to the camera
  wavelength) is added to the frame, and the tilt-removed rms of the residual
  phases is the per-frame truth. A frame is the mean of its steps' unit-flux images.
"""

import numpy as np
import xarray as xr

from ..ao.correction import OpenLoopCorrection
from ..atmosphere.screens import ScreenSet
from ..optics.imaging import Imager
from ..optics.propagation import Propagator
from ..optics.pupil import TiltRemover
from ..progress import Progress
from ..tomography.criterion import LgsRmsEstimator, lucky_frame_rms_nm
from ..units import ARCSEC_RAD, REFERENCE_WAVELENGTH_M, phase_rad_to_nm
from ..wfs.sensor import LgsSensor
from .case import Case
from .datasets import require_finite


def lgs_chain(case: Case, screens: ScreenSet, reconstructors: np.ndarray,
              seed: int) -> tuple[LgsSensor, LgsRmsEstimator]:
    """The case's LGS sensor and its estimator (``reconstructors`` (target, point, slope))."""
    wfs = case.wfs
    sensor = LgsSensor(case.lgs, case.shack_hartmann(), wfs.exposure_steps, list(case.layers), screens, seed,
                       wfs.photons_per_subaperture, wfs.read_noise_e)
    return sensor, LgsRmsEstimator(reconstructors, sensor.n_slopes)


def simulate(case: Case, screens: ScreenSet, write_frames, sensor: LgsSensor | None = None,
             estimator: LgsRmsEstimator | None = None, commands: tuple[np.ndarray, np.ndarray] | None = None,
             block_frames: int = 32) -> xr.Dataset:
    """Run the case; ``write_frames(start, frames (target, k, n, n))`` receives the
    noiseless unit-flux frames. Returns the telemetry dataset. With an LGS
    ``sensor`` and its ``estimator``, each frame also gets its ``lgs_rms_nm``;
    with ``commands`` (the command matrix and the DM slopes of the case's
    ``ao`` settings, :func:`luckyao.study.reconstructor.build_commands`) the DM
    corrects every step and each frame gets its ``lgs_residual_rms_nm``.

    Per frame it records the truth (tilt-removed rms) and the frame's value on
    the optical axis over the diffraction-limited peak, whose mean over frames
    is the long-exposure Strehl (no recentring): a plain mean, so its
    Monte-Carlo error follows from batch means.
    """
    imager = Imager(case.telescope, case.camera)
    mask = imager.mask
    propagator = Propagator(list(case.layers), screens, list(case.targets), imager.grid, mask=mask)
    tilt = TiltRemover.for_mask(imager.grid, mask)
    correction = None
    if commands is not None:
        surface = case.ao.deformable_mirror(case.telescope).grid_surface(imager.grid, mask)
        correction = OpenLoopCorrection(*commands, surface, sensor.exposure_steps, case.ao.delay_steps,
                                        case.steps_per_frame)
    n_targets, n_frames, spf = len(case.targets), case.n_frames, case.steps_per_frame
    steps_max = propagator.n_steps_max if sensor is None else min(propagator.n_steps_max, sensor.n_steps_max)
    if n_frames * spf > steps_max:
        raise ValueError(f"the screens hold {steps_max} steps, the case needs {n_frames * spf}")
    to_camera = np.float32(REFERENCE_WAVELENGTH_M / case.camera.wavelength_m)
    n_pix = case.camera.n_pixels

    true_rms_nm = np.empty((n_targets, n_frames), dtype=np.float32)
    r0_frame = np.empty(n_frames)
    axis_strehl = np.empty((n_targets, n_frames), dtype=np.float32)
    lgs_rms = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    lgs_residual_rms = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    progress = Progress("frames", n_frames)
    buffer = np.empty((n_targets, block_frames, n_pix, n_pix), dtype=np.float32)
    intensity = np.empty((n_targets, imager.fft_size, imager.fft_size), dtype=np.float32)
    for start in range(0, n_frames, block_frames):
        count = min(block_frames, n_frames - start)
        for j in range(count):
            frame = start + j
            steps = frame * spf + np.arange(spf)
            layer_scales = case.layer_scales(steps)
            if sensor is not None:  # LGS sensor -> estimator (-> correction); spf is a multiple of exposure_steps
                e = sensor.exposure_steps
                starts = steps[::e]
                slopes = np.stack([sensor.exposure_slopes(steps[i:i + e], layer_scales[i:i + e])
                                   for i in range(0, spf, e)])
                require_finite(slopes, f"LGS slopes of frame {frame}", "slopes",
                               ("exposure", "beacon", "axis", "subaperture"))
                lgs_rms[:, frame] = lucky_frame_rms_nm(estimator.rms_nm(slopes))
                if correction is not None:
                    for start_step, exposure in zip(starts, slopes):
                        correction.measure(int(start_step), exposure)
                    residual = np.stack([correction.residual_slopes(int(s), exposure)
                                         for s, exposure in zip(starts, slopes)])
                    lgs_residual_rms[:, frame] = lucky_frame_rms_nm(estimator.rms_nm(residual))
            intensity.fill(0.0)  # phase source -> correction -> imager and truth
            rms2 = np.zeros(n_targets)
            phases = propagator.sample_valid(steps, layer_scales)  # (k, n_targets, n_valid)
            require_finite(phases, f"science phases of frame {frame}", "phase", ("step", "target", "sample"))
            for step, phase_500 in zip(steps, phases):
                if correction is not None:
                    phase_500 = phase_500 - correction.surface_at(int(step))
                imager.accumulate(phase_500 * to_camera, intensity)
                rms2 += tilt.rms(phase_500) ** 2
            buffer[:, j] = imager.to_pixels(intensity / spf)
            axis_strehl[:, frame] = buffer[:, j, n_pix // 2, n_pix // 2] / imager.diffraction_limited_peak
            true_rms_nm[:, frame] = phase_rad_to_nm(np.sqrt(rms2 / spf), REFERENCE_WAVELENGTH_M)
            r0_frame[frame] = np.mean(case.r0.r0_m(steps * case.time_step_s))
        write_frames(start, buffer[:, :count])
        progress.update(start + count)

    frame_time = spf * case.time_step_s
    extra = {}
    if sensor is not None:
        extra["lgs_rms_nm"] = (("target", "frame"), lgs_rms, {
            "units": "nm", "long_name": "tilt-removed rms of the LGS tomographic reconstruction along the "
            "target, over the frame's WFS exposures"})
    if correction is not None:
        extra["lgs_residual_rms_nm"] = (("target", "frame"), lgs_residual_rms, {
            "units": "nm", "long_name": "tilt-removed rms of the LGS pseudo-closed-loop reconstruction (open-loop "
            "slopes less the DM's) along the target, over the frame's WFS exposures"})
    return xr.Dataset(
        {
            **extra,
            "true_rms_nm": (("target", "frame"), true_rms_nm,
                            {"units": "nm", "long_name": "tilt-removed rms of the residual (corrected) "
                             "wavefront over the pupil and the frame's exposure"}),
            "r0_500nm_m": (("frame",), r0_frame, {"units": "m", "long_name": "Fried parameter at 500 nm"}),
            "axis_strehl": (("target", "frame"), axis_strehl,
                            {"units": "1", "long_name": "frame value on the optical axis over the "
                             "diffraction-limited peak"}),
        },
        coords={
            "time_s": (("frame",), np.arange(n_frames) * frame_time,
                       {"units": "s", "long_name": "start time of the frame"}),
            "target_x_arcsec": (("target",), [t.theta_x_rad / ARCSEC_RAD for t in case.targets],
                                {"units": "arcsec", "long_name": "target x direction"}),
            "target_y_arcsec": (("target",), [t.theta_y_rad / ARCSEC_RAD for t in case.targets],
                                {"units": "arcsec", "long_name": "target y direction"}),
        },
        attrs={"diffraction_limited_peak": imager.diffraction_limited_peak,
               "pupil_samples": imager.grid.n_pix, "pupil_sample_m": imager.grid.dx_m},
    )
