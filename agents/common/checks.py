"""Checks of the values that the library's functions are called with: one rule each, so that
every function refuses a bad value in the same words ("episodes must be an integer >= 2; got
1.5"). The command lines check their arguments with argparse types (:mod:`agents.common.cli`),
which give argparse's own messages; these are the same rules for callers from Python."""

from __future__ import annotations

from typing import Any

from tether_gym.envs.arguments import MAX_NUM_ENVS
from tether_gym.limits import is_whole_number

__all__ = ["MAX_CHECK_OBSERVATIONS", "MAX_NUM_ENVS", "MAX_TRAINING_SEED", "check_int", "is_count"]

#: The largest seed a training run takes: SB3 and RLlib seed numpy's legacy generator with it
#: (``np.random.seed``: below 2**32), RLlib with the seed plus a runner's offset; 2**31 - 1 leaves
#: those offsets room. A larger one failed after the run directory was made, in numpy's words.
MAX_TRAINING_SEED = 2**31 - 1
#: The most observations a conversion checks (and keeps in reference_actions.safetensors): at 100
#: 000 the largest id's file is 30 MB, well under the 128 MiB a policy directory's safetensors file
#: may have; 10**9 allocated hundreds of GB before the first check.
MAX_CHECK_OBSERVATIONS = 100_000
# MAX_NUM_ENVS (tether_gym's largest vector env) also bounds the counts that become one: a
# trainer's envs, and the episodes of an evaluation, which run as one batch.


def check_int(name: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    """``value`` as an ``int``, or a ``ValueError`` naming ``name`` unless it is a Python or numpy
    integer (not a bool) in ``[minimum, maximum]`` (no upper bound when ``maximum`` is None)."""
    if not is_whole_number(value) or value < minimum or (maximum is not None and value > maximum):
        bound = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
        raise ValueError(f"{name} must be an integer {bound}; got {value!r}")
    return int(value)


def is_count(value: Any) -> bool:
    """Whether ``value`` is a whole number >= 1 (a Python or numpy integer, not a bool)."""
    return is_whole_number(value) and value >= 1
