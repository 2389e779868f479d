"""A figure's settings, typed: the figure's config block (with the schema's defaults),
its cases as :class:`~luckyao.studyspec.case.Case` and a short summary of each."""

from dataclasses import dataclass, field

from ..studyspec.case import Case
from ..studyspec.schema import figure_default

SUMMARISED = {
    "ao.mode",
    "telescope.diameter_m",
    "atmosphere.r0_500nm_m",
    "atmosphere.r0_amplitude_m",
    "atmosphere.layer_variability.sigma_ln",
    "atmosphere.layer_variability.correlation_time_s",
    "atmosphere.layer_variability.seed",
    "wfs.n_subapertures",
    "lgs.enabled",
    "lgs.n_beacons",
    "lgs.height_m",
    "ao.n_actuators",
}
"""The config keys a summary's parts (:meth:`CaseSummary.parts`) already say."""


@dataclass(frozen=True)
class CaseSummary:
    """What tells a case apart in a legend: AO, telescope diameter, r0, LGS WFS, beacons and
    their height, DM."""

    name: str
    ao_mode: str
    r0_cm: float
    r0_varies: bool
    wfs_subapertures: int | None
    dm_actuators: int | None
    lgs_height_km: float | None
    diameter_m: float = 4.2
    n_beacons: int | None = None
    others: tuple[str, ...] = ()
    """``key value`` of every other key the case sets apart from the base (:data:`SUMMARISED` aside)."""
    layers_vary: bool = False
    """Each layer's strength varies in time (``atmosphere.layer_variability``: intermittent turbulence)."""

    @classmethod
    def of(cls, name: str, case: Case, differences: dict | None = None) -> "CaseSummary":
        """``differences``: ``{key path: value}`` the case sets apart from the base, not derived
        (``studyspec.view``)."""
        others = tuple(
            f"{path} {value}" for path, value in sorted((differences or {}).items()) if path not in SUMMARISED
        )
        return cls(
            name=name,
            ao_mode=case.ao.mode,
            r0_cm=100 * case.r0.mean_m,
            r0_varies=case.r0.amplitude_m > 0,
            wfs_subapertures=case.wfs.n_subapertures if case.lgs else None,
            dm_actuators=case.ao.n_actuators if case.ao.mode != "none" else None,
            lgs_height_km=case.lgs.height_m / 1e3 if case.lgs else None,
            diameter_m=case.telescope.diameter_m,
            n_beacons=case.lgs.n_beacons if case.lgs else None,
            others=others,
            layers_vary=case.layer_variability is not None,
        )

    def parts(self) -> dict[str, str]:
        """Short descriptions by aspect, e.g. ``{"ao": "LTAO", "r0": "r0 13.5 cm", ...}``."""
        ao = {"none": "no AO"}.get(self.ao_mode, self.ao_mode.upper())
        r0 = f"r0 {self.r0_cm:g} cm" + (" (varying)" if self.r0_varies else "")
        r0 += " (intermittent layers)" if self.layers_vary else ""
        parts = {"ao": ao, "telescope": f"{self.diameter_m:g} m", "r0": r0}
        if self.wfs_subapertures:
            parts["wfs"] = f"{self.wfs_subapertures}x{self.wfs_subapertures} WFS"
            parts["beacons"] = f"{self.n_beacons} LGS"
            parts["lgs"] = f"LGS {self.lgs_height_km:g} km"
        if self.dm_actuators:
            parts["dm"] = f"{self.dm_actuators}x{self.dm_actuators} DM"
        return parts

    def summary(self) -> str:
        """Every part, then every other key set apart from the base: ``LTAO, 4.2 m, r0 13.5 cm,
        8x8 WFS, 4 LGS, LGS 90 km, 9x9 DM; lgs.profile gaussian, lgs.wavelength_m 5.89e-07``."""
        parts = ", ".join(self.parts().values())
        return f"{parts}; {', '.join(self.others)}" if self.others else parts


def short_labels(summaries: list[CaseSummary]) -> list[str]:
    """Legend labels that say only what differs between the cases (the AO mode always
    when any case has AO); the case names when that leaves two labels equal."""
    parts = [s.parts() for s in summaries]
    aspects = ["ao", "telescope", "r0", "wfs", "beacons", "lgs", "dm"]
    differ = [a for a in aspects if len({p.get(a) for p in parts}) > 1 or (a == "ao" and len(parts) == 1)]
    labels = [", ".join(p[a] for a in differ if a in p) for p in parts]
    if len(set(labels)) < len(labels) or not all(labels):
        return [s.name for s in summaries]
    return labels


@dataclass(frozen=True)
class FigureSettings:
    """A figure's config block (``figures.<id>``) with the schema's defaults, its cases'
    resolved configs, the seed, and what the workflow adds for some kinds: the detector
    sweep's detectors and a sweep's grid points."""

    kind: str
    cases: tuple[str, ...]
    case_configs: dict
    seed: int = 0
    detector: str = field(default_factory=lambda: figure_default("detector"))
    criteria: tuple[str, ...] = ()
    fractions: tuple[float, ...] = ()
    read_noise_e: tuple[float, ...] = ()
    metric: str = "strehl"
    strehl_thresholds: tuple[float, ...] = field(default_factory=lambda: tuple(figure_default("strehl_thresholds")))
    series_labels: tuple[tuple[str, str], ...] = ()
    """(case, series) pairs naming some cases' series (``series_labels``)."""
    window_s: float = field(default_factory=lambda: figure_default("window_s"))
    layer_heights_m: tuple[float, ...] = ()
    pairs: tuple = ()
    sweep: str = ""
    parameter: str = ""
    sweep_points: tuple = ()
    """((case, {key path: value}), ...) of a sweep figure, in grid order, each point's paths in the
    sweep's order (given as (path, value) pairs: the settings' JSON keeps their order)."""
    sweep_detectors: dict = field(default_factory=dict)
    case_differences: dict = field(default_factory=dict)
    """``{case: {key path: value}}``: what each case sets apart from the base (not derived)."""
    photometry: dict = field(default_factory=dict)
    """The study's ``photometry`` block with its defaults (:func:`luckyao.photometry.config_with_defaults`):
    the magnitude scale of the kinds that draw magnitudes (:data:`luckyao.studyspec.lucky.MAGNITUDE_KINDS`);
    empty: the schema's defaults."""

    @classmethod
    def from_dict(cls, settings: dict) -> "FigureSettings":
        known = set(cls.__dataclass_fields__)
        unknown = set(settings) - known
        if unknown:
            raise ValueError(f"figure settings: unknown keys {sorted(unknown)}")
        tuples = {"cases", "criteria", "fractions", "read_noise_e", "layer_heights_m", "pairs", "strehl_thresholds"}
        values = {k: tuple(v) if k in tuples else v for k, v in settings.items()}
        if "series_labels" in values:
            values["series_labels"] = tuple(sorted(values["series_labels"].items()))
        if "sweep_points" in values:
            values["sweep_points"] = tuple((p[0], dict(p[1])) for p in values["sweep_points"])
        return cls(**values)

    def case(self, name: str) -> Case:
        return Case.from_config(self.case_configs[name])

    def summaries(self) -> list[CaseSummary]:
        return [CaseSummary.of(name, self.case(name), self.case_differences.get(name)) for name in self.cases]


def case_coords(settings: FigureSettings, datasets=()) -> dict:
    """The ``case`` coordinate of a figure's dataset with what the drawing needs of each
    case: its mean r0 (the lucky dataset's, else the config's), short legend label, full
    summary, AO mode and colour index (its place in the figure)."""
    summaries = settings.summaries()
    r0_cm = [100 * float(ds["mean_r0_500nm_m"]) for ds in datasets] if datasets else [s.r0_cm for s in summaries]
    return {
        "case": ("case", list(settings.cases), {"long_name": "case"}),
        "r0_cm": ("case", r0_cm, {"units": "cm", "long_name": "mean Fried parameter at 500 nm"}),
        "label": ("case", short_labels(summaries), {"long_name": "legend label (what differs between the cases)"}),
        "summary": ("case", [s.summary() for s in summaries], {"long_name": "the case in short"}),
        "ao_mode": ("case", [s.ao_mode for s in summaries], {"long_name": "AO correction: none, ltao or glao"}),
        "colour": ("case", list(range(len(summaries))), {"units": "1", "long_name": "colour index in the palette"}),
    }
