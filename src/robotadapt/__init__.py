"""robotadapt: adaptive control of rigid robot manipulators (layers: docs/architecture.md)."""

from importlib.metadata import version

from ._moved import install

__version__ = version("robotadapt")
install()
