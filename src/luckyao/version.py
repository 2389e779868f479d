"""The package's version: the installed distribution's, or ``0+unknown`` in a source tree."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("luckyao")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0+unknown"
