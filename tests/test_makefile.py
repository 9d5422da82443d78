"""The README's two commands do what the README says: `make test` installs system packages only through the
`system-packages` step, which names each package before apt-get runs and is skipped by SYSTEM_PACKAGES=0."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def recipe(target: str) -> str:
    """The recipe of a Makefile target, its continuation lines joined and its white space collapsed."""
    text = (ROOT / "Makefile").read_text()
    match = re.search(rf"^{re.escape(target)}:.*\n((?:\t.*\n)*)", text, flags=re.MULTILINE)
    assert match, target
    return " ".join(match.group(1).replace("\\\n", " ").split())


def test_the_test_target_installs_nothing_itself():
    assert "apt-get" not in recipe("test")
    prerequisites = re.search(r"^test:([^#\n]*)", (ROOT / "Makefile").read_text(), flags=re.MULTILINE)
    assert prerequisites and "system-packages" in prerequisites.group(1).split()


def test_each_system_package_is_named_before_apt_get_installs_it():
    steps = recipe("system-packages")
    for package in ("chromium", "libosmesa6"):
        announce = steps.find(f"apt-get install {package} (")
        install = steps.find(f"install -y -qq {package}")
        assert -1 < announce < install, package
    assert "SYSTEM_PACKAGES=0" in steps


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_system_packages_0_skips_every_install():
    out = subprocess.run(["make", "-s", "system-packages", "SYSTEM_PACKAGES=0"], cwd=ROOT, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "system packages: skipped (SYSTEM_PACKAGES=0); the browser and video tests skip"
