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

import dataclasses
import json

import numpy as np
import xarray as xr

from ..ao.apodisation import Apodiser, DelayedApodisation, SubapertureRegions
from ..ao.budget import PARTS, ResidualBudget, telemetry_variables
from ..ao.control import ground_layers
from ..ao.correction import DelayedDm, OpenLoopCorrection
from ..ao.laser_criteria import FRAME_CRITERIA, TARGET_CRITERIA, LaserCriteria
from ..atmosphere.screens import ScreenSet
from ..io.datasets import open_dataset, require_finite
from ..layer_tomography.correction import LayerCorrection, LayerEstimator
from ..optics.imaging import Imager
from ..optics.propagation import Propagator
from ..optics.pupil import TiltRemover
from ..progress import Progress
from ..studyspec.case import Case
from ..studyspec.products import lgs_spec
from ..tomography.criterion import LgsRmsEstimator, lucky_frame_rms_nm
from ..tomography.reconstructor import factorize, reconstruction_points, target_reconstructor
from ..tomography.slopes import SlopeGeometry, slope_covariance
from ..units import ARCSEC_RAD, REFERENCE_WAVELENGTH_M, phase_rad_to_nm
from ..wfs.sensor import LgsSensor
from .lgs_slopes import lgs_sensor


def lgs_chain(
    case: Case, screens: ScreenSet, reconstructors: np.ndarray, seed: int, calibration=None
) -> tuple[LgsSensor, LgsRmsEstimator]:
    """The case's LGS sensor (:func:`.lgs_slopes.lgs_sensor`) and its estimator (``reconstructors``
    (target, point, slope))."""
    sensor = lgs_sensor(case, screens, seed, calibration)
    return sensor, LgsRmsEstimator(reconstructors, sensor.n_slopes)


def laser_criteria_of(case: Case, reconstructors: np.ndarray) -> LaserCriteria:
    """The laser-only criteria (:mod:`luckyao.ao.laser_criteria`) of an AO case whose targets'
    reconstructors (target, point, slope) are ``reconstructors``: its reconstructors restricted
    to the ground and the altitude layers built here (a factorisation of the slope covariance,
    seconds for the default WFS)."""
    wfs, tomography = case.shack_hartmann(), case.tomography
    prior, noise_rad = tomography.prior, tomography.noise_rms_rad
    geometry = SlopeGeometry.from_wfs(wfs, case.lgs)
    points = reconstruction_points(case.telescope, wfs.subaperture_m, tomography.points_per_subaperture)
    noise = case.slope_noise_covariance_rad2(wfs)
    cholesky = factorize(slope_covariance(prior, geometry, noise_rad, noise_covariance_rad2=noise))
    ground = ground_layers(prior, case.ao.glao_max_height_m)
    altitude = [i for i in range(len(prior.heights_m)) if i not in ground]
    layers = [
        [
            target_reconstructor(
                prior,
                geometry,
                noise_rad,
                points,
                (t.theta_x_rad, t.theta_y_rad),
                layer_indices=indices,
                cholesky_lower=cholesky,
            )
            for t in case.targets
        ]
        for indices in (ground, altitude)
    ]
    dm = case.ao.deformable_mirror(case.telescope)
    influence = dm.influence_matrix(points[:, 0], points[:, 1])
    return LaserCriteria(reconstructors, layers, influence, dm.fit_matrix(points), points, wfs.subaperture_m)


def twin_lgs_rms_nm(path, config: dict, seed: int) -> np.ndarray:
    """The ``lgs_rms_nm`` (target, frame) of the telemetry file ``path`` of a case's LGS twin
    (:func:`luckyao.studyspec.products.lgs_twin`), after checking that it measured them with the
    case's own LGS chain and seed."""
    telemetry = open_dataset(path, "LGS twin telemetry", allow_nan={"axis_strehl", "lgs_residual_rms_nm"})
    twin = json.loads(telemetry.attrs["config_json"])
    if lgs_spec(twin) != lgs_spec(config) or int(telemetry.attrs["seed"]) != seed:
        raise ValueError(
            f"'{path}' was not measured with this case's LGS chain and seed {seed}: "
            f"its lgs_rms cannot stand for this case's"
        )
    return telemetry["lgs_rms_nm"].values


class SciencePath:
    """Phase source -> correction -> imager and truth, for some of a case's targets.

    ``targets``: indices into ``case.targets`` propagated (each gets its truth); ``imaged``:
    indices into ``targets`` also imaged. :meth:`frame` computes one lucky frame.
    """

    def __init__(self, case: Case, screens: ScreenSet, targets, imaged):
        self.case = case
        self.imager = imager = Imager(case.telescope, case.camera)
        self.targets, self.imaged = list(targets), list(imaged)
        self.propagator = Propagator(
            list(case.layers), screens, [case.targets[t] for t in self.targets], imager.grid, mask=imager.mask
        )
        self.tilt = TiltRemover.for_mask(imager.grid, imager.mask)
        self.to_camera = np.float32(REFERENCE_WAVELENGTH_M / case.camera.wavelength_m)
        self._all_imaged = self.imaged == list(range(len(self.targets)))
        self._intensity = np.empty((len(self.imaged), imager.fft_size, imager.fft_size), dtype=np.float32)
        self._oracle, self.transmitted_flux = False, 1.0

    def dm_surface(self):
        """The DM surface function at this path's pupil samples (the case must have AO)."""
        ao, telescope = self.case.ao, self.case.telescope
        return ao.deformable_mirror(telescope).grid_surface(self.imager.grid, self.imager.mask)

    def frame(
        self,
        frame: int,
        steps: np.ndarray,
        layer_scales: np.ndarray,
        dm=None,
        truth: bool = True,
        apodisation: DelayedApodisation | None = None,
        budget: ResidualBudget | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The frame's images (imaged, n, n) float32 (the mean of its steps' images, of unit
        flux for the full pupil), their value on the axis (imaged,) (:meth:`Imager.axis_value`)
        and, with ``truth``, the tilt-removed rms (targets,) [rad at 500 nm] of its residual
        phases over the whole pupil; ``dm`` (anything with ``surface_at(step)``) corrects every
        step, ``apodisation`` (with the oracle driver fed the first target's true phases here)
        apodises it: the transmitted flux of the frame is then :attr:`transmitted_flux`; ``budget``
        is fed the first target's uncorrected phase of every step."""
        self._intensity.fill(0.0)
        rms2 = np.zeros(len(self.targets)) if truth else None
        phases = self.propagator.sample_valid(steps, layer_scales)  # (k, n_targets, n_valid)
        require_finite(phases, f"science phases of frame {frame}", "phase", ("step", "target", "sample"))
        transmission, self.transmitted_flux = None, 0.0
        for step, phase_500 in zip(steps, phases):
            if apodisation is not None:
                if self._oracle:
                    apodisation.observe(int(step), phase_500[0])
                transmission = apodisation.at(int(step))
                self.transmitted_flux += float(np.mean(transmission)) / len(steps)
            if budget is not None:
                budget.step(int(step), phase_500[0])
            if dm is not None:
                phase_500 = phase_500 - dm.surface_at(int(step))
            imaged = phase_500 if self._all_imaged else phase_500[self.imaged]
            self.imager.accumulate(
                imaged * self.to_camera,
                self._intensity,
                None if transmission is None else np.broadcast_to(transmission, imaged.shape),
            )
            if truth:
                rms2 += self.tilt.rms(phase_500) ** 2
        images = self.imager.to_pixels(self._intensity / self.case.steps_per_frame)
        return (
            images,
            self.imager.axis_value(images),
            None if rms2 is None else np.sqrt(rms2 / self.case.steps_per_frame),
        )

    def apodisation(self, dm: DelayedDm) -> DelayedApodisation | None:
        """The case's adaptive apodisation of this path's pupil, timed by ``dm`` (None without)."""
        settings, case = self.case.ao.apodisation, self.case
        if settings is None:
            return None
        x, y = self.imager.grid.xy_m
        x, y = x[self.imager.mask], y[self.imager.mask]
        regions = SubapertureRegions(case.telescope.diameter_m, case.wfs.n_subapertures)
        apodiser = Apodiser(regions, x, y, settings.blocked_fraction)
        self._oracle = settings.driver == "oracle"
        if self._oracle:
            return DelayedApodisation(apodiser, dm, self.tilt)
        points = self.reconstruction_points()
        return DelayedApodisation(
            apodiser, dm, self.tilt, regions.labels(points[:, 0], points[:, 1]), TiltRemover(points[:, 0], points[:, 1])
        )

    def reconstruction_points(self) -> np.ndarray:
        """The LGS reconstructors' pupil points (n_points, 2) [m] (``study.reconstructor``)."""
        case = self.case
        return reconstruction_points(
            case.telescope, case.shack_hartmann().subaperture_m, case.tomography.points_per_subaperture
        )


def simulate(
    case: Case,
    screens: ScreenSet,
    write_frames,
    sensor: LgsSensor | None = None,
    estimator: LgsRmsEstimator | LayerEstimator | None = None,
    commands: tuple[np.ndarray, np.ndarray] | None = None,
    imaged_targets=None,
    block_frames: int = 32,
    lgs_rms_nm: np.ndarray | None = None,
    budget_sensor: LgsSensor | None = None,
    laser: LaserCriteria | None = None,
) -> xr.Dataset:
    """Run the case; ``write_frames(start, frames (imaged target, k, n, n))`` receives the
    noiseless unit-flux frames of ``imaged_targets`` (indices into ``case.targets``,
    default all; every target gets its truth). Returns the telemetry dataset. With an LGS
    ``sensor`` (or its recorded slopes, :class:`.lgs_slopes.RecordedSlopes`) and its ``estimator``, each frame also
    gets its ``lgs_rms_nm``; a case
    without AO may instead be given them (target, frame), as measured by a case with the
    same LGS chain (:func:`luckyao.studyspec.products.lgs_twin`);
    with ``commands`` (the command matrix and the DM slopes of the case's
    ``ao`` settings, :func:`luckyao.steps.reconstructor.build_commands`), or an AO case's
    iterative ``estimator`` (:class:`luckyao.layer_tomography.correction.LayerEstimator`, whose
    layer estimates give the commands: ``tomography.method: iterative``), the DM
    corrects every step, each frame gets its ``lgs_residual_rms_nm`` and every
    exposure's DM commands are recorded (``dm_commands_m``), so that the science path
    of the targets not imaged can be replayed (:class:`Replay`). With AO and a
    ``budget_sensor`` (the LGS sensor's twin without noise) each frame also gets the
    residual budget of the first target (:mod:`luckyao.ao.budget`); with AO and ``laser``
    (:func:`laser_criteria_of`) each frame also gets the laser-only criteria
    (:mod:`luckyao.ao.laser_criteria`).

    Per frame it records the truth (tilt-removed rms) and the imaged targets' frame
    value on the optical axis over the diffraction-limited peak, whose mean over frames
    is the long-exposure Strehl (no recentring): a plain mean, so its
    Monte-Carlo error follows from batch means.
    """
    n_targets, n_frames, spf, clock = len(case.targets), case.n_frames, case.steps_per_frame, case.clock
    if sensor is not None and sensor.exposure_steps != clock.exposure_steps:
        raise ValueError(
            f"the LGS sensor's exposures are {sensor.exposure_steps} steps, the case's {clock.exposure_steps}"
        )
    imaged = list(range(n_targets)) if imaged_targets is None else sorted(imaged_targets)
    science = SciencePath(case, screens, range(n_targets), imaged)
    imager = science.imager
    correction = apodisation = None
    timing = (clock.exposure_steps, case.ao.delay_steps, spf) if case.ao is not None else None
    if commands is not None:
        correction = OpenLoopCorrection(*commands, science.dm_surface(), *timing)
    elif isinstance(estimator, LayerEstimator) and estimator.projection is not None:
        correction = LayerCorrection(estimator.projection, science.dm_surface(), *timing)
    if correction is not None:
        dm_commands = np.empty((clock.n_exposures, correction.dm.n_actuators), np.float32)
        apodisation = science.apodisation(correction.dm)
        if apodisation is not None and apodisation.point_labels is not None:  # LGS driver
            points = science.reconstruction_points()
            dm_at_points = (
                case.ao.deformable_mirror(case.telescope)
                .influence_matrix(points[:, 0], points[:, 1])
                .astype(np.float32)
            )  # (n_points, n_act) [m / m]
    budget = None
    if budget_sensor is not None:
        if commands is None or sensor is None:
            raise ValueError(
                "the residual budget needs AO with the dense command matrix and the LGS sensor (or its recorded slopes)"
            )
        budget = ResidualBudget(
            case.ao.deformable_mirror(case.telescope),
            commands[0],
            budget_sensor,
            imager.grid,
            imager.mask,
            correction.dm,
        )
        budget_rms_nm = np.empty((len(PARTS), n_frames))
        budget_cross_nm2 = np.empty(n_frames)
    if laser is not None:
        if commands is None or sensor is None:
            raise ValueError(
                "the laser criteria need AO with the dense command matrix and the LGS sensor (or its recorded slopes)"
            )
        laser_target_nm = np.empty((len(TARGET_CRITERIA), n_targets, n_frames), dtype=np.float32)
        laser_frame_nm = np.empty((len(FRAME_CRITERIA), n_frames), dtype=np.float32)
    steps_max = science.propagator.n_steps_max
    if sensor is not None:
        steps_max = min(steps_max, sensor.n_steps_max)
    if clock.n_steps > steps_max:
        raise ValueError(f"the screens hold {steps_max} steps, the case needs {clock.n_steps}")
    n_pix = case.camera.n_pixels

    true_rms_nm = np.empty((n_targets, n_frames), dtype=np.float32)
    r0_frame = np.empty(n_frames)
    axis_strehl = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    if lgs_rms_nm is not None:
        if sensor is not None or commands is not None or np.shape(lgs_rms_nm) != (n_targets, n_frames):
            raise ValueError(
                f"given LGS telemetry needs a case without AO or sensor and shape "
                f"{(n_targets, n_frames)}, got {np.shape(lgs_rms_nm)}"
            )
        lgs_rms = np.asarray(lgs_rms_nm, dtype=np.float32)
    else:
        lgs_rms = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    lgs_residual_rms = np.full((n_targets, n_frames), np.nan, dtype=np.float32)
    transmitted = np.empty(n_frames, dtype=np.float32)
    progress = Progress("frames", n_frames)
    buffer = np.empty((len(imaged), block_frames, n_pix, n_pix), dtype=np.float32)
    for start in range(0, n_frames, block_frames):
        count = min(block_frames, n_frames - start)
        for j in range(count):
            frame = start + j
            steps = clock.steps(frame)
            layer_scales = case.layer_scales(steps)
            if sensor is not None:  # LGS sensor -> estimator (-> correction); a frame holds whole exposures
                e = clock.exposure_steps
                starts = clock.exposure_starts(steps)
                slopes = np.stack(
                    [
                        sensor.exposure_slopes(steps[i : i + e], layer_scales[i : i + e])
                        for i in clock.exposure_offsets()
                    ]
                )
                require_finite(
                    slopes, f"LGS slopes of frame {frame}", "slopes", ("exposure", "beacon", "axis", "subaperture")
                )
                estimates = estimator.estimate(slopes)  # the slopes; the iterative path's layers
                lgs_rms[:, frame] = lucky_frame_rms_nm(estimator.rms_nm(estimates))
                if correction is not None:
                    for i, start_step, exposure, estimate in zip(clock.exposure_offsets(), starts, slopes, estimates):
                        dm_commands[clock.exposure(start_step)] = correction.measure(int(start_step), estimate)
                        if budget is not None:
                            budget.exposure(int(start_step), steps[i : i + e], layer_scales[i : i + e], exposure)
                        if apodisation is not None and apodisation.point_labels is not None:
                            apodisation.from_estimate(
                                int(start_step),
                                estimator.reconstructors[0] @ exposure.ravel(),
                                dm_at_points @ dm_commands[clock.exposure(start_step)],
                            )
                    residual = correction.residual_rms_nm(starts, estimates, estimator)
                    lgs_residual_rms[:, frame] = lucky_frame_rms_nm(residual)
                    if laser is not None:
                        laser_target_nm[:, :, frame], laser_frame_nm[:, frame] = laser.frame(
                            slopes, dm_commands[clock.frame_exposures(frame)]
                        )
            buffer[:, j], axis_strehl[imaged, frame], rms = science.frame(
                frame, steps, layer_scales, correction, apodisation=apodisation, budget=budget
            )
            if budget is not None:
                budget_rms_nm[:, frame], budget_cross_nm2[frame] = budget.frame_rms_nm()
            if apodisation is not None:
                transmitted[frame] = science.transmitted_flux
            true_rms_nm[:, frame] = phase_rad_to_nm(rms, REFERENCE_WAVELENGTH_M)
            r0_frame[frame] = np.mean(case.r0_m(steps))
        write_frames(start, buffer[:, :count])
        progress.update(start + count)

    frame_time = spf * case.time_step_s
    extra = {}
    if sensor is not None or lgs_rms_nm is not None:
        extra["lgs_rms_nm"] = (
            ("target", "frame"),
            lgs_rms,
            {
                "units": "nm",
                "long_name": "tilt-removed rms of the LGS tomographic reconstruction along the "
                "target, over the frame's WFS exposures",
            },
        )
    if correction is not None:
        extra["lgs_residual_rms_nm"] = (
            ("target", "frame"),
            lgs_residual_rms,
            {
                "units": "nm",
                "long_name": (
                    "tilt-removed rms of the LGS pseudo-closed-loop reconstruction (open-loop layer estimate "
                    "less the applied DM shape) along the target, over the frame's WFS exposures"
                    if isinstance(correction, LayerCorrection)
                    else "tilt-removed rms of the LGS pseudo-closed-loop reconstruction (open-loop "
                    "slopes less the DM's) along the target, over the frame's WFS exposures"
                ),
            },
        )
        if apodisation is not None:
            extra["transmitted_flux"] = (
                ("frame",),
                transmitted,
                {
                    "units": "1",
                    "long_name": "flux through the adaptively apodised pupil over the full pupil's, "
                    f"mean over the frame's steps (blocked fraction of the pupil area: 1 minus it); driver "
                    f"{case.ao.apodisation.driver}",
                },
            )
        if budget is not None:
            extra.update(telemetry_variables(budget_rms_nm, budget_cross_nm2))
        if laser is not None:
            for (name, long_name), values in zip(TARGET_CRITERIA, laser_target_nm):
                extra[f"{name}_nm"] = (("target", "frame"), values, {"units": "nm", "long_name": long_name})
            for (name, long_name), values in zip(FRAME_CRITERIA, laser_frame_nm):
                extra[f"{name}_nm"] = (("frame",), values, {"units": "nm", "long_name": long_name})
        extra["dm_commands_m"] = (
            ("exposure", "actuator"),
            dm_commands,
            {
                "units": "m",
                "long_name": "DM commands of each WFS exposure (applied from delay_steps after its "
                "start), valid actuators",
            },
        )
    return xr.Dataset(
        {
            **extra,
            "true_rms_nm": (
                ("target", "frame"),
                true_rms_nm,
                {
                    "units": "nm",
                    "long_name": "tilt-removed rms of the residual (corrected) "
                    "wavefront over the pupil and the frame's exposure",
                },
            ),
            "r0_500nm_m": (("frame",), r0_frame, {"units": "m", "long_name": "Fried parameter at 500 nm"}),
            "axis_strehl": (
                ("target", "frame"),
                axis_strehl,
                {
                    "units": "1",
                    "long_name": "frame value on the optical axis over the "
                    "diffraction-limited peak (NaN: target not imaged by the simulation)",
                },
            ),
        },
        coords={
            "time_s": (
                ("frame",),
                np.arange(n_frames) * frame_time,
                {"units": "s", "long_name": "start time of the frame"},
            ),
            "target_x_arcsec": (
                ("target",),
                [t.theta_x_rad / ARCSEC_RAD for t in case.targets],
                {"units": "arcsec", "long_name": "target x direction"},
            ),
            "target_y_arcsec": (
                ("target",),
                [t.theta_y_rad / ARCSEC_RAD for t in case.targets],
                {"units": "arcsec", "long_name": "target y direction"},
            ),
            "imaged": (
                ("target",),
                np.isin(np.arange(n_targets), imaged).astype(np.int8),
                {"units": "1", "long_name": "target imaged (frames written) by the simulation"},
            ),
        },
        attrs={
            "diffraction_limited_peak": imager.diffraction_limited_peak,
            "pupil_samples": imager.grid.n_pix,
            "pupil_sample_m": imager.grid.dx_m,
        },
    )


class TimeLoop:
    """A case's time loop composed from its products: the one composition, which the workflow's
    ``simulate`` step (so :func:`luckyao.run_case`, which runs that step) and the benchmarks use.

    The LGS chain: ``slopes`` (an AO case's recorded slopes, :class:`.lgs_slopes.RecordedSlopes`)
    replayed, or else, with ``reconstructors`` (target, point, slope), the case's sensor measured
    in the loop with ``seed`` and the WFS ``calibration`` (:func:`lgs_chain`); its estimator from
    ``reconstructors``. Without either, none: a no-AO case may be given its twin's ``lgs_rms_nm``
    (target, frame) (:func:`twin_lgs_rms_nm`). ``commands`` (the command matrix and the DM
    slopes) with AO; ``imaged_targets`` as :func:`simulate`'s. With ``tomography.method:
    iterative`` no reconstructors or commands: the estimator and, with AO, the DM commands come
    from the layer tomography built here
    (:meth:`luckyao.layer_tomography.correction.LayerEstimator.for_case`), the sensor (unless
    its slopes are replayed or its ``lgs_rms_nm`` given) measured in the loop. With ``ao.residual_budget`` the
    budget's noiseless sensor, with ``ao.laser_criteria`` the laser criteria
    (:func:`laser_criteria_of`). Built here (the sensor's set-up
    takes seconds, which a benchmark leaves out of its timing); :meth:`run` runs it once.
    """

    def __init__(
        self,
        case: Case,
        screens: ScreenSet,
        seed: int,
        *,
        reconstructors: np.ndarray | None = None,
        calibration=None,
        slopes=None,
        commands: tuple[np.ndarray, np.ndarray] | None = None,
        lgs_rms_nm: np.ndarray | None = None,
        imaged_targets=None,
    ):
        self.case, self.screens, self.commands = case, screens, commands
        self.lgs_rms_nm, self.imaged_targets = lgs_rms_nm, imaged_targets
        self.sensor = self.estimator = None
        if case.tomography.iterative:
            if reconstructors is not None or commands is not None:
                raise ValueError("tomography.method: iterative builds its own estimator: give no dense products")
            if slopes is not None or (case.lgs is not None and lgs_rms_nm is None):
                self.sensor = slopes if slopes is not None else lgs_sensor(case, screens, seed, calibration)
                self.estimator = LayerEstimator.for_case(case)
                if self.estimator.n_slopes != self.sensor.n_slopes:
                    raise ValueError("the layer tomography does not match this WFS")
        elif slopes is not None:
            self.sensor, self.estimator = slopes, LgsRmsEstimator(reconstructors, slopes.n_slopes)
        elif reconstructors is not None:
            self.sensor, self.estimator = lgs_chain(case, screens, reconstructors, seed, calibration)
        self.budget_sensor = None
        if case.ao is not None and case.ao.residual_budget:
            noiseless = dataclasses.replace(case, wfs=dataclasses.replace(case.wfs, photons_per_subaperture=None))
            self.budget_sensor = lgs_sensor(noiseless, screens, seed, calibration)
        self.laser = None
        if case.ao is not None and case.ao.laser_criteria:
            self.laser = laser_criteria_of(case, reconstructors)

    def run(self, write_frames) -> xr.Dataset:
        """:func:`simulate` of the case (``write_frames`` as there): its telemetry."""
        return simulate(
            self.case,
            self.screens,
            write_frames,
            self.sensor,
            self.estimator,
            self.commands,
            self.imaged_targets,
            lgs_rms_nm=self.lgs_rms_nm,
            budget_sensor=self.budget_sensor,
            laser=self.laser,
        )


class Replay:
    """The science path of some of a case's targets replayed frame by frame, corrected by the
    recorded DM commands: called, an iterator of ``(start, frames (target, k, n, n))``, and the
    frames' value on the axis (:meth:`Imager.axis_value`) in :attr:`axis_strehl` (target,
    frame) once they have been made. Recomputing these frames is as fast as simulating them
    and stores nothing: the frames of a field case's off-axis targets are made where they are
    used (post-processing), not kept on disk."""

    def __init__(
        self, case: Case, screens: ScreenSet, targets, dm_commands_m: np.ndarray | None, block_frames: int = 64
    ):
        """``targets``: indices into ``case.targets``; ``dm_commands_m`` (exposure, actuator) of
        :func:`simulate`, None without AO."""
        self.case, self.screens, self.targets = case, screens, list(targets)
        self.dm_commands_m, self.block_frames = dm_commands_m, block_frames
        self.axis_strehl = np.full((len(self.targets), case.n_frames), np.nan, dtype=np.float32)

    def __call__(self):
        case = self.case
        if case.ao.apodisation is not None:
            raise ValueError(
                "replaying an adaptively apodised case (ao.apodisation) is not supported: image all "
                "its targets in the simulation"
            )
        clock = case.clock
        science = SciencePath(case, self.screens, self.targets, range(len(self.targets)))
        dm = None
        if self.dm_commands_m is not None:
            dm = DelayedDm(science.dm_surface(), clock.exposure_steps, case.ao.delay_steps, clock.steps_per_frame)
        block = np.empty((len(self.targets), self.block_frames) + (case.camera.n_pixels,) * 2, dtype=np.float32)
        for start in range(0, case.n_frames, self.block_frames):
            count = min(self.block_frames, case.n_frames - start)
            for j in range(count):
                steps = clock.steps(start + j)
                if dm is not None:
                    for step in clock.exposure_starts(steps):
                        dm.apply(int(step), self.dm_commands_m[clock.exposure(step)])
                block[:, j], self.axis_strehl[:, start + j], _ = science.frame(
                    start + j, steps, case.layer_scales(steps), dm, truth=False
                )
            yield start, block[:, :count].copy()
