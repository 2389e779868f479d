"""Lucky imaging of a frame cube: detector noise, image metrics, selection and shift-and-add.

Public objects, by module --
detector: Detector, apply_detector, KeyedNoise, detect, detector_key; metrics: strehl, fwhm_arcsec,
d50_arcsec, EncircledEnergy; selection: run_lucky, ExternalCriterion, ImageReference, rank_frames,
shift_and_add; kernels: the compiled noise, encircled-energy and accumulation loops.
"""
