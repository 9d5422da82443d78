"""Scenarios: the book's examples and problems as TOML files, and the loader that validates them."""

from .build import Setup
from .loader import Scenario, available, load

__all__ = ["Scenario", "Setup", "available", "load"]
