"""Optional dependencies: import one, or fail with an error that names the extra which installs it.

The core package needs only numpy, gymnasium and numba; plots, training, the multi-agent API and
the rest come with pip extras (pyproject's ``[project.optional-dependencies]``). A bare
``ModuleNotFoundError: No module named 'yaml'`` tells a user neither why the module is wanted nor
which extra brings it, so every optional import of both packages (``tether_gym`` and
``tether_gym_agents``) goes through :func:`require`::

    yaml = require("yaml", "train", "reading the hyperparameter files")

which returns the module, or raises :class:`MissingExtraError` with the line that installs it.
Module-level imports that keep their ``from x import y`` form go in a :func:`needs_extra` block::

    with needs_extra("train", "training and loading policies"):
        import torch
        from stable_baselines3 import PPO
"""

from __future__ import annotations

import contextlib
import importlib
import types
from collections.abc import Iterator

# The pip name of each optional module whose import name differs from it, for the message's
# "pip install X" alternative. Modules not listed install under their import name.
_DISTRIBUTIONS = {
    "yaml": "pyyaml",
    "stable_baselines3": "stable-baselines3",
    "sb3_contrib": "sb3-contrib",
    "ray": "ray[rllib]",
    "PIL": "pillow",
}


#: Top-level packages of this project: a module of theirs that is missing is a broken checkout or
#: install, which no extra fixes.
_OWN_PACKAGES = frozenset({"tether_gym", "tether_gym_agents", "agents"})


class MissingExtraError(ModuleNotFoundError):
    """An optional module is not installed. A ``ModuleNotFoundError`` (so an ``ImportError``) too,
    so that code which catches those keeps working; the message names the extra to install.

    Attributes: ``name`` is the module that is missing, ``extra`` the pip extra that installs it.
    """

    def __init__(self, message: str, *, name: str, extra: str) -> None:
        super().__init__(message, name=name)
        self.extra = extra


def install_line(extra: str) -> str:
    """The shell command that installs the extra ``extra`` of a released tether-gym (quoted for
    the shell: the brackets are glob characters in zsh)."""
    return f'pip install "tether-gym[{extra}]"'


def missing_message(module: str, extra: str, purpose: str) -> str:
    """The message of a :class:`MissingExtraError` for ``module`` (as :func:`require` words it)."""
    top = module.partition(".")[0]
    distribution = _DISTRIBUTIONS.get(top, top)
    return (
        f"{top} is not installed; it is needed for {purpose}. Install it with {install_line(extra)} "
        f"(in a checkout: pip install -e '.[{extra}]'; or this package alone: pip install '{distribution}')"
    )


def require(module: str, extra: str, purpose: str) -> types.ModuleType:
    """Import and return ``module`` (a dotted name such as ``"matplotlib.pyplot"``).

    Args:
        module: the module to import.
        extra: the pip extra of tether-gym that installs it (``"train"``, ``"plots"``, ...).
        purpose: what needs it, to end the phrase "it is needed for ...": ``"the LQR baseline"``.

    Raises:
        MissingExtraError: ``module`` or a package above it is not installed (or blocked with
            ``sys.modules[name] = None``). The message names the module, ``purpose`` and the line
            ``pip install "tether-gym[<extra>]"``.
        ImportError: the module is installed but one of *its* imports fails (a broken install):
            that error is passed on unchanged, since installing the extra would not fix it.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as error:
        # Only the module asked for, or a package above it: a dependency missing inside an
        # installed module is a broken install, and naming our extra would mislead.
        parts = module.split(".")
        wanted = {".".join(parts[: index + 1]) for index in range(len(parts))}
        if error.name not in wanted:
            raise
        raise MissingExtraError(missing_message(module, extra, purpose), name=module, extra=extra) from error


@contextlib.contextmanager
def needs_extra(extra: str, purpose: str) -> Iterator[None]:
    """A block of imports that the extra ``extra`` provides: a third-party module missing in it
    (or in what it imports) raises :class:`MissingExtraError` naming the module, ``purpose`` and
    ``pip install "tether-gym[<extra>]"``. A missing module of this project's own packages, and a
    :class:`MissingExtraError` raised deeper (which names its own extra), pass unchanged."""
    try:
        yield
    except MissingExtraError:
        raise
    except ModuleNotFoundError as error:
        if error.name is None or error.name.partition(".")[0] in _OWN_PACKAGES:
            raise
        raise MissingExtraError(missing_message(error.name, extra, purpose), name=error.name, extra=extra) from error


def available(module: str) -> bool:
    """Whether ``module`` can be imported (without raising); for optional features that are
    skipped, not required, when their module is absent."""
    try:
        importlib.import_module(module)
    except ModuleNotFoundError:
        return False
    return True
