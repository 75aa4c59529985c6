"""The versions of the packages that a result depends on, as recorded beside it: in a policy's
``policy.json`` (what trained and can load it) and in a benchmark's ``benchmark.json`` (what the
numbers were computed with). One reader serves both; each record names its own packages."""

from __future__ import annotations

import platform
from collections.abc import Sequence
from importlib import metadata

__all__ = ["BENCHMARK_PACKAGES", "POLICY_PACKAGES", "package_versions"]

#: What a benchmark's numbers depend on: the simulator, the statistics and the learners.
BENCHMARK_PACKAGES = ("tether-gym", "numpy", "scipy", "rliable", "arch", "stable-baselines3", "torch")
#: What a policy file was written with, under the names its ``policy.json`` has always used.
POLICY_PACKAGES = ("stable_baselines3", "torch", "numpy", "gymnasium", "tether_gym", "python")


def package_versions(packages: Sequence[str]) -> dict[str, str]:
    """``{name: version}`` of the installed distributions ``packages`` (as named there), in that
    order; "not installed" for one that is missing. A name with underscores is looked up as the
    distribution of that name with dashes (``stable_baselines3`` is ``stable-baselines3``);
    ``python`` is the interpreter's version."""
    versions = {}
    for package in packages:
        if package == "python":
            versions[package] = platform.python_version()
            continue
        try:
            versions[package] = metadata.version(package.replace("_", "-"))
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions
