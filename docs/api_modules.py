"""The modules of the API reference (``docs/api.rst``), by subpackage: the one list to edit
when a module moves. autodoc documents each module's public objects (names without a
leading underscore that have a docstring) from their docstrings.

Written against the package layout of issue 39 (``studyspec/``, ``steps/``, ``io/``,
``figures/``, ``jobs/``, ``archive/``, ``cli.py`` and ``version.py`` at the root).
"""

API_MODULES = {
    "The Python interface": ["luckyao.api", "luckyao.version"],
    "Atmosphere": ["luckyao.atmosphere.statistics", "luckyao.atmosphere.screens"],
    "Geometry, seeds and units": ["luckyao.geometry", "luckyao.seeds", "luckyao.units"],
    "Optics": [
        "luckyao.optics.pupil",
        "luckyao.optics.propagation",
        "luckyao.optics.imaging",
        "luckyao.optics.farfield",
        "luckyao.optics.long_exposure",
    ],
    "Wavefront sensing": [
        "luckyao.wfs.beacons",
        "luckyao.wfs.shack_hartmann",
        "luckyao.wfs.detector",
        "luckyao.wfs.centroiders",
        "luckyao.wfs.calibration",
        "luckyao.wfs.sensor",
    ],
    "Tomography": [
        "luckyao.tomography.prior",
        "luckyao.tomography.slopes",
        "luckyao.tomography.reconstructor",
        "luckyao.tomography.criterion",
        "luckyao.layer_tomography.grids",
        "luckyao.layer_tomography.operators",
        "luckyao.layer_tomography.prior",
        "luckyao.layer_tomography.noise",
        "luckyao.layer_tomography.preconditioner",
        "luckyao.layer_tomography.solver",
        "luckyao.layer_tomography.projection",
        "luckyao.layer_tomography.assembly",
        "luckyao.layer_tomography.correction",
    ],
    "Adaptive optics": ["luckyao.ao.dm", "luckyao.ao.control", "luckyao.ao.correction", "luckyao.ao.apodisation"],
    "Lucky imaging": [
        "luckyao.lucky.detector",
        "luckyao.lucky.metrics",
        "luckyao.lucky.ranking",
        "luckyao.lucky.registration",
        "luckyao.lucky.scoring",
        "luckyao.lucky.pipeline",
        "luckyao.lucky.fourier",
    ],
    "Study configuration": [
        "luckyao.studyspec.schema",
        "luckyao.studyspec.study",
        "luckyao.studyspec.sweeps",
        "luckyao.studyspec.scaling",
        "luckyao.studyspec.products",
        "luckyao.studyspec.lucky",
        "luckyao.studyspec.resolved",
        "luckyao.studyspec.yamlfile",
        "luckyao.studyspec.case",
        "luckyao.studyspec.lucky_settings",
    ],
    "Time loop and cached products": [
        "luckyao.steps.screens",
        "luckyao.steps.calibration",
        "luckyao.steps.reconstructor",
        "luckyao.steps.lgs_slopes",
        "luckyao.steps.simulation",
        "luckyao.steps.postprocess",
    ],
    "Input and output": ["luckyao.io.datasets", "luckyao.io.fits", "luckyao.io.hashing", "luckyao.io.kinds"],
    "Figures": [
        "luckyao.figures",
        "luckyao.figures.settings",
        "luckyao.figures.style",
        "luckyao.figures.colour_vision",
    ],
    "Workflow infrastructure": [
        "luckyao.jobs.code_deps",
        "luckyao.jobs.resources",
        "luckyao.jobs.live_run",
        "luckyao.jobs.progress",
        "luckyao.jobs.report",
    ],
    "Archive and verify": ["luckyao.archive.create", "luckyao.archive.verify"],
    "Command line": ["luckyao.cli"],
}
