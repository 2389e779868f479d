"""luckyao: LGS-assisted lucky imaging, simulated and validated against theory."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("luckyao")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0+unknown"
