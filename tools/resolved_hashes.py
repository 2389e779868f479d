"""Print what names a study's cached results: every case's resolved-config hash, product keys,
LGS twin and lucky-settings hash, and each figure's legend labels and summaries, for the shipped
configs. Run before and after a change to the config code and diff the two outputs:

    .venv/bin/python tools/resolved_hashes.py > after.txt
"""

from luckyao.figures.settings import CaseSummary, short_labels
from luckyao.io.hashing import sha256
from luckyao.studyspec.case import Case
from luckyao.studyspec.study import read_study, validate_study
from luckyao.studyspec.sweeps import expand_study
from luckyao.studyspec.view import resolve_study

STUDIES = {
    "default": ["config/config.yaml"],
    "paper": ["config/config.yaml", "config/paper.yaml"],
    "diameter": ["config/config.yaml", "config/diameter.yaml"],
    "diameter_full": ["config/config.yaml", "config/diameter.yaml", "config/diameter_full.yaml"],
    "apodisation": ["config/config.yaml", "config/apodisation.yaml"],
    "uncalibrated": ["config/config.yaml", "config/uncalibrated.yaml"],
    "tiny": ["tests/data/tiny.yaml"],
}

for label, paths in STUDIES.items():
    study = expand_study(read_study(*paths))
    view = resolve_study(study, validate_study(study))
    for name, case in sorted(view.cases.items()):
        keys = [case.screens.key] + [
            product.key if product else "-"
            for product in (case.reconstructor, case.commands, case.calibration, case.slopes)
        ]
        print(
            label,
            name,
            case.config_sha256[:16],
            *keys,
            f"twin={case.lgs_twin}",
            f"lucky={sha256(case.lucky_settings)[:16]}",
        )
    for fig, figure in study["figures"].items():
        summaries = [CaseSummary.of(n, Case.from_config(view.cases[n].config)) for n in figure["cases"]]
        print(label, "figure", fig, "labels=", short_labels(summaries))
        print(label, "figure", fig, "summaries=", [s.summary() for s in summaries])
