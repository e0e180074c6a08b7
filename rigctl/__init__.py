"""rigctl: run a planar camera array on set and turn its takes into colour + per-pixel depth."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rigctl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
