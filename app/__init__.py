"""The application: live sessions, recordings, replay, export, batch, the CLI and the window."""

from importlib.metadata import PackageNotFoundError, version

try:
    APP_VERSION = version("imucap")  # what a recording says made it
except PackageNotFoundError:  # a checkout on the path without an install
    APP_VERSION = "0.0.0+unknown"
