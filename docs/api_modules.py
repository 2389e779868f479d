"""The modules of the API reference (``docs/api.rst``), by subpackage: the one list to edit
when a module moves. autodoc documents each module's public objects (names without a
leading underscore that have a docstring) from their docstrings.

Written against the package layout of issue 39 (``spec/``, ``steps/``, ``io/``,
``figures/``, ``jobs/``, ``archive/``, ``cli.py`` and ``version.py`` at the root).
"""

API_MODULES = {
    "The Python interface": ["luckyao.api", "luckyao.version"],
    "Atmosphere": ["luckyao.atmosphere.statistics", "luckyao.atmosphere.screens"],
    "Geometry, seeds and units": ["luckyao.geometry", "luckyao.seeds", "luckyao.units"],
    "Optics": ["luckyao.optics.pupil", "luckyao.optics.propagation", "luckyao.optics.imaging",
               "luckyao.optics.farfield", "luckyao.optics.long_exposure"],
    "Wavefront sensing": ["luckyao.wfs.beacons", "luckyao.wfs.shack_hartmann", "luckyao.wfs.detector",
                          "luckyao.wfs.centroiders", "luckyao.wfs.calibration", "luckyao.wfs.sensor"],
    "Tomography": ["luckyao.tomography.prior", "luckyao.tomography.slopes",
                   "luckyao.tomography.reconstructor", "luckyao.tomography.criterion"],
    "Adaptive optics": ["luckyao.ao.dm", "luckyao.ao.control", "luckyao.ao.correction",
                        "luckyao.ao.apodisation"],
    "Lucky imaging": ["luckyao.lucky.detector", "luckyao.lucky.metrics", "luckyao.lucky.ranking",
                      "luckyao.lucky.registration", "luckyao.lucky.scoring", "luckyao.lucky.pipeline"],
    "Study configuration": ["luckyao.spec.schema", "luckyao.spec.study", "luckyao.spec.sweeps",
                            "luckyao.spec.scaling", "luckyao.spec.products", "luckyao.spec.lucky",
                            "luckyao.spec.case", "luckyao.spec.lucky_settings"],
    "Time loop and cached products": ["luckyao.steps.screens", "luckyao.steps.calibration",
                                      "luckyao.steps.reconstructor", "luckyao.steps.lgs_slopes",
                                      "luckyao.steps.simulation", "luckyao.steps.postprocess"],
    "Input and output": ["luckyao.io.datasets", "luckyao.io.fits"],
    "Figures": ["luckyao.figures", "luckyao.figures.settings", "luckyao.figures.style"],
    "Workflow infrastructure": ["luckyao.jobs.code_deps", "luckyao.jobs.resources",
                                "luckyao.jobs.live_run", "luckyao.jobs.report"],
    "Archive and verify": ["luckyao.archive.archive", "luckyao.archive.verify"],
    "Command line": ["luckyao.cli"],
}

# The same subpackages in the tree before the restructure (for a build against it:
# ``LUCKYAO_DOCS_LAYOUT=study bash docs/build.sh``); remove once the restructure is merged.
BEFORE_RESTRUCTURE = {
    "luckyao.version": None,
    "luckyao.spec.schema": "luckyao.study.config", "luckyao.spec.study": None,
    "luckyao.spec.sweeps": "luckyao.study.sweeps", "luckyao.spec.scaling": "luckyao.study.scaling",
    "luckyao.spec.products": None, "luckyao.spec.lucky": None,
    "luckyao.spec.case": "luckyao.study.case", "luckyao.spec.lucky_settings": "luckyao.study.lucky_settings",
    "luckyao.steps.screens": "luckyao.study.turbulence", "luckyao.steps.calibration": "luckyao.study.calibration",
    "luckyao.steps.reconstructor": "luckyao.study.reconstructor",
    "luckyao.steps.lgs_slopes": "luckyao.study.lgs_slopes", "luckyao.steps.simulation": "luckyao.study.simulation",
    "luckyao.steps.postprocess": "luckyao.study.postprocess",
    "luckyao.io.datasets": "luckyao.study.datasets", "luckyao.io.fits": "luckyao.study.export",
    "luckyao.figures": "luckyao.study.figures", "luckyao.figures.settings": "luckyao.study.figures.settings",
    "luckyao.figures.style": "luckyao.study.figures.style",
    "luckyao.jobs.code_deps": "luckyao.study.code_deps", "luckyao.jobs.resources": "luckyao.study.resources",
    "luckyao.jobs.live_run": "luckyao.study.live_run", "luckyao.jobs.report": "luckyao.study.report",
    "luckyao.archive.archive": "luckyao.study.archive", "luckyao.archive.verify": "luckyao.study.verify",
    "luckyao.cli": "luckyao.study.cli",
}
