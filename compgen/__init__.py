"""compgen: find where a five-axis machine's rotary axes really are, from R-test data."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("compgen")
except PackageNotFoundError:   # a source checkout that was never installed
    __version__ = "0+unknown"
