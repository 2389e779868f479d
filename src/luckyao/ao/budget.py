"""The residual budget of an AO case: the true residual along the first target, split step by
step into parts whose vector sum is that residual (``ao.residual_budget``).

At science step ``t`` the DM holds the commands ``c = M s`` of exposure ``e`` (the one
:meth:`.correction.DelayedDm.source_step` names), ``s`` its measured slopes. With ``phi`` the
true phase along the target, ``F`` the least-squares DM fit at the science samples
(:meth:`.dm.DeformableMirror.fit_matrix`, no piston/tip/tilt) and ``H`` the DM surface, every
phase in rad at 500 nm:

* **fitting** ``phi(t) - H F phi(t)``: what the DM cannot represent;
* **servo lag** ``H F phi(t) - H F <phi>_e``: how the DM-fitted phase moved between the
  exposure (its mean ``<>_e`` over the exposure's steps) and the step it corrects (the delay
  and the exposure's own averaging);
* **tomography** ``H F <phi>_e - H M s_ideal``: what the reconstructor makes of ideal
  measurements short of the DM-fitted target phase: the cone effect, turbulence the beacons
  do not sample, the finite layers and the prior's regularisation, and for GLAO the layers
  it leaves uncorrected by design. ``s_ideal = Grad(H_w F_w <psi_b>_e)``: the mean gradient
  (:func:`mean_gradient_matrix`) of each beacon's DM-fitted downlink phase ``psi_b`` over the
  exposure: noise-free and alias-free;
* **aliasing** ``-H M Grad(<psi_b>_e - H_w F_w <psi_b>_e)``: the slopes of what the DM cannot
  represent, reconstructed as if it could;
* **sensor** ``-H M (s_noiseless - Grad <psi_b>_e)``: the physical-optics Shack-Hartmann
  (elongated spots, the uplink, the centroider and its calibration) against the geometric
  mean gradient, without noise;
* **noise** ``-H M (s - s_noiseless)``: photon and read noise; ``s_noiseless`` from a twin
  sensor without noise on the same phases.

The parts telescope: their sum is ``phi(t) - H c``, the true residual (before the first
command, ``c = 0``: all but fitting and servo lag vanish and servo lag is ``H F phi(t)``).
Each part's frame value is its tilt-removed rms (the truth's, ``true_rms_nm``) over the
frame's steps. The fitting part is orthogonal to the DM-space parts up to the piston/tip/tilt
the DM's commands leave at the science samples, so its cross terms vanish; the DM-space
parts are not mutually orthogonal (servo lag and tomography, aliasing and noise correlate):
``residual_cross_nm2``, the frame's total variance less the parts' sum, holds what remains.
"""

import numpy as np
import scipy.sparse
import xarray as xr

from ..optics.pupil import PupilGrid, TiltRemover
from ..units import REFERENCE_WAVELENGTH_M, phase_rad_to_nm
from .correction import DelayedDm
from .dm import DeformableMirror

PARTS = ("fitting", "tomography", "aliasing", "servo_lag", "sensor", "noise")
"""The parts of the residual, in the order of :meth:`ResidualBudget.frame_rms_nm`."""

_SLOPE_PARTS = ("tomography", "aliasing", "sensor", "noise")
"""The parts that come with an exposure's slopes (each its commands' surface)."""


def mean_gradient_matrix(wfs) -> scipy.sparse.csr_array:
    """``G`` (2 n_valid, n_sensed) float64 [1 / m], sparse: each valid sub-aperture's mean x and
    y gradient of a phase on the WFS grid's sensed samples (``wfs.sensed_mask``, row-major) over
    its sensed area, as the sensor's centroid sees it: along each run of ``m`` neighbouring
    sensed samples the edge-to-edge difference over its ``m dx`` (the end samples' differences
    extrapolated half a sample out, so a linear phase is exact), the runs weighted by length."""
    n_s, n = wfs.samples_per_subaperture, wfs.grid.n_pix
    sensed = wfs.sensed_mask
    index = np.full((n, n), -1)
    index[sensed] = np.arange(int(sensed.sum()))
    rows, columns, values = [], [], []
    for v, (iy, ix) in enumerate(wfs.subaperture_index):
        block = index[iy * n_s : (iy + 1) * n_s, ix * n_s : (ix + 1) * n_s]
        for axis, lines in enumerate((block, block.T)):
            entries, length = [], 0
            for line in lines:
                for run in np.split(line, np.flatnonzero(line < 0)):
                    run = run[run >= 0]
                    m = len(run)
                    if m < 2:
                        continue
                    weights = np.ones(m - 1) if m > 2 else np.array([2.0])
                    weights[[0, -1]] = 1.5 if m > 2 else 2.0
                    entries += [(run[1:], weights), (run[:-1], -weights)]
                    length += m
            for samples, weights in entries:
                rows.append(np.full(len(samples), axis * wfs.n_valid + v))
                columns.append(samples)
                values.append(weights / (length * wfs.grid.dx_m))
    shape = (2 * wfs.n_valid, int(sensed.sum()))
    coo = scipy.sparse.coo_array((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))), shape)
    return coo.tocsr()  # duplicates summed


def _without_beacon_tilt(slopes: np.ndarray) -> np.ndarray:
    """Slopes (n_beacons, 2, n_valid) less each beacon's mean x and y slope, as measured."""
    return slopes - slopes.mean(axis=-1, keepdims=True)


class ResidualBudget:
    """The parts (:data:`PARTS`) of the true residual along a case's first target.

    ``dm`` and ``command_matrix`` (n_act, n_slopes) [m / rad] are the case's; ``sensor``: a twin
    of the case's LGS sensor without noise (:class:`luckyao.wfs.sensor.LgsSensor`); ``grid`` and
    ``mask`` the science pupil samples; ``delayed`` the loop's DM (its timing). Feed it each
    exposure's measured slopes (:meth:`exposure`) before the steps they correct, and each
    science step's phase (:meth:`step`); :meth:`frame_rms_nm` closes a frame.
    """

    def __init__(
        self,
        dm: DeformableMirror,
        command_matrix: np.ndarray,
        sensor,
        grid: PupilGrid,
        mask: np.ndarray,
        delayed: DelayedDm,
    ):
        wfs = sensor.wfs
        self.sensor, self.delayed = sensor, delayed
        self.command_matrix = np.asarray(command_matrix, dtype=np.float32)
        self._to_rad = np.float32(2 * np.pi / REFERENCE_WAVELENGTH_M)
        x, y = wfs.grid.xy_m
        sensed = wfs.sensed_mask
        wfs_points = np.stack([x[sensed], y[sensed]], axis=1)
        self._sensed = np.flatnonzero(sensed)
        # phase [rad at 500 nm] -> slopes [rad] (sparse: each sub-aperture's edges), and the DM
        # fit of the beacons' phases -> its slopes
        gradient = mean_gradient_matrix(wfs) / float(self._to_rad)
        self._gradient = gradient.astype(np.float32)
        self._wfs_fit = dm.fit_matrix(wfs_points).astype(np.float32)
        self._fit_slopes = (gradient @ dm.influence_matrix(wfs_points[:, 0], wfs_points[:, 1])).astype(np.float32)
        x, y = grid.xy_m
        self._fit = dm.fit_matrix(np.stack([x[mask], y[mask]], axis=1)).astype(np.float32)
        self._surface = dm.grid_surface(grid, mask)
        self.tilt = TiltRemover.for_mask(grid, mask)
        self._slope_surfaces = {}  # exposure start -> (4, n_samples) the surfaces H M s of _SLOPE_PARTS
        self._fitted_sums = {}  # exposure start -> sum of F phi over its steps (n_act,)
        self._mean_surfaces = {}  # exposure start -> H F <phi>_e (n_samples,)
        self._power = np.zeros(len(PARTS) + 1)  # the parts' and their sum's tilt-removed power over the frame
        self._steps = 0

    def exposure(self, start_step: int, steps, layer_scales, slopes: np.ndarray) -> None:
        """The exposure starting at ``start_step`` (its ``steps`` and ``layer_scales``, as the
        sensor's) and its measured slopes (n_beacons, 2, n_valid) [rad]."""
        noiseless = self.sensor.exposure_slopes(steps, layer_scales)
        n_b = noiseless.shape[0]
        phases = self.sensor.downlink_phases.reshape(len(steps), n_b, -1)[:, :, self._sensed].mean(axis=0)
        geometric = _without_beacon_tilt((self._gradient @ phases.T).T.reshape(noiseless.shape))
        ideal = _without_beacon_tilt((phases @ self._wfs_fit.T @ self._fit_slopes.T).reshape(noiseless.shape))
        chain = np.stack([ideal, geometric - ideal, noiseless - geometric, slopes - noiseless])
        commands = chain.reshape(len(chain), -1) @ self.command_matrix.T * self._to_rad
        self._slope_surfaces[start_step] = np.stack([self._surface(c) for c in commands]).astype(np.float32)

    def step(self, step: int, phase: np.ndarray) -> None:
        """The uncorrected phase (n_samples,) [rad at 500 nm] along the target at ``step``."""
        fitted = self._fit @ phase
        start = step - step % self.delayed.exposure_steps
        self._fitted_sums[start] = self._fitted_sums.get(start, 0.0) + fitted
        fitted_surface = self._surface(fitted).astype(np.float32)
        parts = np.zeros((len(PARTS) + 1, phase.size), dtype=np.float32)
        parts[PARTS.index("fitting")] = phase - fitted_surface
        source = self.delayed.source_step(step)
        if source < 0:
            parts[PARTS.index("servo_lag")] = fitted_surface
        else:
            if source not in self._mean_surfaces:
                mean = self._fitted_sums[source] / self.delayed.exposure_steps
                self._mean_surfaces[source] = self._surface(mean).astype(np.float32)
            mean_surface, surfaces = self._mean_surfaces[source], self._slope_surfaces[source]
            parts[PARTS.index("servo_lag")] = fitted_surface - mean_surface
            parts[PARTS.index("tomography")] = mean_surface - surfaces[0]
            for name, surface in zip(_SLOPE_PARTS[1:], surfaces[1:]):
                parts[PARTS.index(name)] = -surface
            for stored in (self._slope_surfaces, self._fitted_sums, self._mean_surfaces):
                for key in [k for k in stored if k < source]:
                    del stored[key]
        parts[-1] = parts[:-1].sum(axis=0)
        self._power += self.tilt.rms(parts) ** 2
        self._steps += 1

    def frame_rms_nm(self) -> tuple[np.ndarray, float]:
        """The frame's tilt-removed rms (len(PARTS),) [nm] of each part over its steps, and
        its cross terms [nm^2] (the sum's power less the parts'); starts the next frame."""
        power = self._power / self._steps
        self._power[:], self._steps = 0.0, 0
        rms_nm = phase_rad_to_nm(np.sqrt(power), REFERENCE_WAVELENGTH_M)
        return rms_nm[:-1], float(rms_nm[-1] ** 2 - np.sum(rms_nm[:-1] ** 2))


def telemetry_variables(rms_nm: np.ndarray, cross_nm2: np.ndarray, target: int = 0) -> dict:
    """The telemetry variables of a run's budget: ``residual_<part>_rms_nm`` (frame,) from
    ``rms_nm`` (part, frame) and ``residual_cross_nm2`` (frame,)."""
    variables = {
        f"residual_{name}_rms_nm": (
            ("frame",),
            rms_nm[i].astype(np.float32),
            {
                "units": "nm",
                "long_name": f"tilt-removed rms of the {name.replace('_', ' ')} part of the true residual along "
                f"target {target} over the frame's steps (luckyao.ao.budget)",
            },
        )
        for i, name in enumerate(PARTS)
    }
    variables["residual_cross_nm2"] = (
        ("frame",),
        cross_nm2.astype(np.float32),
        {
            "units": "nm2",
            "long_name": f"cross terms of the residual parts along target {target}: the tilt-removed power of "
            "their sum (the true residual) less the sum of theirs, mean over the frame's steps",
        },
    )
    return variables


def first_corrected_frame(case) -> int:
    """The first frame of a case (:class:`luckyao.studyspec.case.Case`) whose every step holds
    a command: the ones before hold the flat DM's steps, whose servo lag is the whole
    DM-fitted phase."""
    return -(-case.ao.delay_steps // case.steps_per_frame)


def budget_statistics(dataset: xr.Dataset, strehl: np.ndarray, target: int = 0, from_frame: int = 0) -> xr.Dataset:
    """Per part of a telemetry's (or ``lucky.nc``'s) residual budget, its ``cross`` terms and
    the ``total`` (``true_rms_nm`` of ``target``), over the frames from ``from_frame`` (e.g.
    :func:`first_corrected_frame`): the mean variance [nm^2] over frames, the
    frame-to-frame variance [nm^4] of the frame variance, its share of the total's
    frame-to-frame variance (``cov(part, total) / var(total)`` of the frame variances: the
    parts' and the cross terms' shares sum to 1) and the correlation (Pearson) of the frame
    variance with ``strehl`` (frame,), the frame's short-exposure Strehl ratio."""
    if "residual_cross_nm2" not in dataset:
        raise ValueError("this dataset has no residual budget: run the case with ao.residual_budget: true")
    variances = [dataset[f"residual_{name}_rms_nm"].values.astype(float) ** 2 for name in PARTS]
    variances.append(dataset["residual_cross_nm2"].values.astype(float))
    variances.append(dataset["true_rms_nm"].values[target].astype(float) ** 2)
    variances = np.array(variances)[:, from_frame:]
    strehl = np.asarray(strehl, dtype=float)[from_frame:]
    centred = variances - variances.mean(axis=1, keepdims=True)
    total = centred[-1]
    strehl = strehl - np.mean(strehl)
    with np.errstate(invalid="ignore", divide="ignore"):  # a part zero in every frame (noise without noise)
        correlation = centred @ strehl / np.sqrt(np.sum(centred**2, axis=1) * np.sum(strehl**2))
    return xr.Dataset(
        {
            "mean_variance_nm2": (("part",), variances.mean(axis=1), {"units": "nm2"}),
            "frame_variance_nm4": (("part",), variances.var(axis=1), {"units": "nm4"}),
            "share_of_total_fluctuation": (
                ("part",),
                centred @ total / (total @ total),
                {"units": "1", "long_name": "cov(part, total) / var(total) of the frame variances"},
            ),
            "strehl_correlation": (
                ("part",),
                correlation,
                {"units": "1", "long_name": "Pearson correlation of the frame variance with the frame's Strehl ratio"},
            ),
        },
        coords={"part": [*PARTS, "cross", "total"]},
        attrs={"target": target, "from_frame": from_frame, "n_frames": variances.shape[1]},
    )
