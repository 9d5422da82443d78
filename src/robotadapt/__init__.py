"""robotadapt: adaptive control of rigid robot manipulators (layers: docs/architecture.md)."""

from ._moved import install

install()
