"""Scenarios: the book's examples and problems as TOML files, and the loader that validates them."""

from .build import Setup
from .loader import Scenario, available, book_scenarios, load

__all__ = ["Scenario", "Setup", "available", "book_scenarios", "load"]
