"""The installed package's version ("0.0.0+source" in a source tree that was not installed)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wavewarp")
except PackageNotFoundError:
    __version__ = "0.0.0+source"
