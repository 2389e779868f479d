"""Questions asked of a resolved case config: the targets its simulation images, the
selection criteria it can give (its frames: :mod:`luckyao.clock`)."""


def imaged_targets(case: dict) -> list[int]:
    """Indices of the targets a resolved case's simulation images and stores: every target,
    or with a ``reference_target`` and several targets only that one (the star); the
    others are replayed where they are post-processed, so a field's frames never all
    sit on disk."""
    reference, n_targets = case.get("reference_target"), len(case["targets_arcsec"])
    return list(range(n_targets)) if reference is None or n_targets == 1 else [reference]


def criteria_of(case: dict) -> set[str]:
    """Selection criteria a resolved case gives: image criteria always, ``lgs_rms`` with
    LGS, ``lgs_residual_rms`` and the oracle ``true_rms`` with AO, the laser-only criteria
    with ``ao.laser_criteria`` and ``learned`` with ``ao.learned_training_seed``."""
    criteria = {"strehl", "d50"}
    if case["lgs"]["enabled"]:
        criteria.add("lgs_rms")
    if case["ao"]["mode"] != "none":
        criteria |= {"lgs_residual_rms", "true_rms"}
    if case["ao"].get("laser_criteria"):
        from ..ao.laser_criteria import FRAME_CRITERIA, TARGET_CRITERIA  # numba: only for the cases asking

        criteria |= {name for name, _ in TARGET_CRITERIA + FRAME_CRITERIA}
    if "learned_training_seed" in case["ao"]:
        criteria.add("learned")
    return criteria
