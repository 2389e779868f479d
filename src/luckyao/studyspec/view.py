"""A study resolved once, at the edge: its cases and their cached products as frozen objects.

:func:`resolve_study` takes a validated study (``studyspec.study.validate_study``: sweeps
expanded, the schema's defaults, the derived keys) and gives a :class:`ResolvedStudy`: each
case's resolved config (the dict its hashes are taken of, unchanged), the keys it derived, what
differs from ``base``, its products (each a :class:`Product` whose ``key`` names its file, the
keys of :mod:`.products`), its screens' length, its LGS twin and its lucky settings (its
detectors and registration methods). The workflow, the CLI and the API read this view.
"""

from dataclasses import dataclass
from typing import ClassVar

from ..io.hashing import sha256
from .lucky import lucky_settings
from .products import (
    calibration_key,
    calibration_spec,
    commands_key,
    commands_spec,
    lgs_twin,
    reconstructor_key,
    reconstructor_spec,
    screens_durations,
    slopes_key,
    slopes_spec,
    turbulence_key,
    turbulence_spec,
)
from .scaling import derived_case, derived_keys, training_case
from .schema import deep_merge
from .study import drawn_cases, unused_cases
from .sweeps import expand_study


@dataclass(frozen=True, eq=False)
class Product:
    """A cached product: its spec (the dict its key hashes, as :mod:`.products` builds it)."""

    spec: dict
    folder: ClassVar[str]
    """Its folder under ``results/``."""
    _key: ClassVar = None

    @property
    def key(self) -> str:
        return type(self)._key(self.spec)

    @property
    def path(self) -> str:
        return f"results/{self.folder}/{self.key}.nc"


class Screens(Product):
    """The normalised phase screens (``.npy``, and their metadata ``.nc``)."""

    folder = "turbulence"
    _key = staticmethod(turbulence_key)

    @property
    def samples_path(self) -> str:
        return f"results/{self.folder}/{self.key}.npy"

    @property
    def duration_s(self) -> float:
        return self.spec["duration_s"]


class Reconstructor(Product):
    folder = "reconstructors"
    _key = staticmethod(reconstructor_key)


class Commands(Product):
    folder = "commands"
    _key = staticmethod(commands_key)


class Calibration(Product):
    folder = "calibrations"
    _key = staticmethod(calibration_key)


class Slopes(Product):
    folder = "slopes"
    _key = staticmethod(slopes_key)


def _product(kind: type[Product], spec: dict | None) -> Product | None:
    return None if spec is None else kind(spec)


@dataclass(frozen=True, eq=False)
class TrainingTwin:
    """The run that trains a case's ``learned`` criterion (``ao.learned_training_seed``): the same
    case with the training seed, so its own screens, LGS slopes and layer strengths in time
    (``config``: :func:`.scaling.training_case`); its reconstructor, command matrix and WFS
    calibration are the case's (the same instrument)."""

    seed: int
    config: dict
    screens: Screens
    slopes: Slopes


def _training_twin(study: dict, case: dict, duration_s: float) -> TrainingTwin | None:
    """A case's :class:`TrainingTwin`, or None without ``ao.learned_training_seed``."""
    seed = case["ao"].get("learned_training_seed")
    if seed is None:
        return None
    twin_study, twin_case = {**study, "seed": seed}, training_case(case, seed)
    screens = turbulence_spec(twin_study, twin_case, duration_s)
    return TrainingTwin(seed, twin_case, Screens(screens), Slopes(slopes_spec(twin_study, twin_case, screens)))


@dataclass(frozen=True, eq=False)
class ResolvedCase:
    """One case, resolved: its config, what it derived and changed, its products and settings."""

    name: str
    config: dict
    """The resolved case config (every key; the dict hashed into ``config_sha256``)."""
    derived: dict
    """``{key path: value}`` of the keys it left out and got derived (``scaling.derived_keys``)."""
    differences: dict
    """``{key path: value}`` of every key whose resolved value differs from ``base``'s."""
    screens: Screens
    reconstructor: Reconstructor | None
    commands: Commands | None
    calibration: Calibration | None
    slopes: Slopes | None
    lgs_twin: str | None
    """The AO case whose simulation measures this no-AO case's LGS telemetry (``products.lgs_twin``)."""
    lucky_settings: dict
    """Its lucky job's settings (``studyspec.lucky.lucky_settings``)."""
    training: TrainingTwin | None = None
    """The run that trains its ``learned`` criterion (``ao.learned_training_seed``), or None."""

    @property
    def detectors(self) -> tuple[str, ...]:
        """The detectors its lucky job applies (the sweep's too when ``lucky.detector_sweep.cases`` lists it)."""
        return tuple(self.lucky_settings["detectors"])

    @property
    def registrations(self) -> tuple[str, ...]:
        return tuple(self.lucky_settings["registration"])

    @property
    def config_sha256(self) -> str:
        return sha256(self.config)

    @property
    def prior_pinned(self) -> bool:
        """Whether the case pins the tomography's prior r0 (else it follows the case's r0)."""
        return "tomography.prior_r0_500nm_m" not in self.derived

    def products(self) -> dict[str, Product]:
        """``{kind: product}`` of the products it has, screens first."""
        kinds = ("screens", "reconstructor", "commands", "calibration", "slopes")
        return {kind: getattr(self, kind) for kind in kinds if getattr(self, kind) is not None}


@dataclass(frozen=True, eq=False)
class ResolvedStudy:
    """A study's config (sweeps expanded) and its resolved cases, by name."""

    config: dict
    cases: dict

    @property
    def configs(self) -> dict:
        """``{case: resolved config}`` (what ``validate_study`` returns)."""
        return {name: case.config for name, case in self.cases.items()}

    @property
    def drawn(self) -> list[str]:
        """The cases a figure reads (``study.drawn_cases``)."""
        return drawn_cases(self.config)

    @property
    def unused(self) -> list[str]:
        """The cases no figure lists (``study.unused_cases``)."""
        return unused_cases(self.config)


def flat(config: dict, prefix: str = "") -> dict:
    """``{key path: value}`` of a nested dict's leaves (lists are values)."""
    out = {}
    for key, value in config.items():
        path = f"{prefix}.{key}" if prefix else key
        out.update(flat(value, path) if isinstance(value, dict) else {path: value})
    return out


def resolve_study(study: dict, configs: dict) -> ResolvedStudy:
    """The view of a validated study: ``study`` (its sweeps expanded here if not yet) and
    ``configs``, its resolved cases (``validate_study(study)``)."""
    study = expand_study(study)
    base = flat(derived_case(study["base"], "base"))
    durations = screens_durations(study, configs)
    screens = {name: turbulence_spec(study, case, durations[name]) for name, case in configs.items()}
    cases = {}
    for name, case in configs.items():
        merged = deep_merge(study["base"], study["cases"][name])
        cases[name] = ResolvedCase(
            name=name,
            config=case,
            derived=derived_keys(merged, case),
            differences={path: value for path, value in flat(case).items() if base.get(path) != value},
            screens=Screens(screens[name]),
            reconstructor=_product(Reconstructor, reconstructor_spec(case)),
            commands=_product(Commands, commands_spec(case)),
            calibration=_product(Calibration, calibration_spec(study, case)),
            slopes=_product(Slopes, slopes_spec(study, case, screens[name])),
            lgs_twin=lgs_twin(study, configs, name, screens),
            lucky_settings=lucky_settings(study, configs, name),
            training=_training_twin(study, case, durations[name]),
        )
    return ResolvedStudy(study, cases)
