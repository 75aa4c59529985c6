"""The agents' command lines: every command's argument parser, and the argument types they share.

The parsers live here, apart from the commands' modules, because those import torch,
Stable-Baselines3 and scipy, which take seconds: a command module run as ``__main__`` (by
``python -m`` or its console script, :mod:`agents.common.commands`) first parses its command line with
:func:`parse_before_imports`, so ``--help`` and a mistyped option answer at once, before any of
that is imported. This module imports only the standard library and :mod:`tether_gym` (for the
ids; the package import itself, numba included, is the 0.3 s that remain).

Help texts name paths as the installed package has them (``tether_gym_agents/hyperparams/...``;
``agents/...`` in a checkout: ``__package__`` is whichever it is imported as).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import difflib
import math
import sys
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from .checks import MAX_CHECK_OBSERVATIONS, MAX_NUM_ENVS, MAX_TRAINING_SEED
from .commands import PACKAGE, description, program
from .data import PACKAGE_DIR

__all__ = [
    "HELD_OUT_SEED",
    "REFERENCE",
    "REFERENCE_FILE",
    "TRAIN_ALGORITHMS",
    "add_allow_other_id_argument",
    "add_env_argument",
    "build_parser",
    "did_you_mean",
    "existing_file",
    "float_between",
    "int_at_least",
    "parse_before_imports",
]

#: First held-out seed of the comparison and the benchmark (10 000 up; training evaluates on
#: 1 000 000 up, agents.training.selection).
HELD_OUT_SEED = 10_000
#: The controller that scores 100 in the benchmark by default: the model-predictive reference.
REFERENCE = "mpc"
#: Where agents.convert --reference keeps the observations and actions it checked.
REFERENCE_FILE = "reference_actions.safetensors"
#: The SB3 algorithms agents.train trains (the keys of agents.policies.format.ALGORITHMS, which
#: imports SB3; a test keeps the two equal).
TRAIN_ALGORITHMS = ("ppo", "sac", "td3")
#: The algorithm name of agents.train_rllib's runs (the run directory's prefix and config.yml's
#: ``algo``) and of its hyperparameter file.
RLLIB_ALGO = "rllib_ppo"


def int_at_least(minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse ``type`` for whole numbers >= ``minimum`` (and <= ``maximum``, if given): a bad
    value is reported by argparse under the option's name ("argument --episodes: must be at least
    2; got 1")."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer; got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}; got {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}; got {value}")
        return value

    return parse


def float_between(low: float, high: float) -> Callable[[str], float]:
    """An argparse ``type`` for finite numbers in [``low``, ``high``]: NaN, infinities and values
    outside are reported by argparse under the option's name."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number; got {text!r}") from None
        if not math.isfinite(value) or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be a finite number in [{low:g}, {high:g}]; got {text}")
        return value

    return parse


def path_argument(text: str) -> str:
    """An argparse ``type`` for a path the command reads or writes: an empty or blank one (an
    unset shell variable, ``--out "$OUT"``) named the current directory, so a command wrote its
    outputs there, or read it as a checkpoint; a NUL character raised a bare ``ValueError`` from
    the operating system's path functions. Both are reported under the option's name."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"must be a path; got {text!r} (an empty path would mean the current directory)"
        )
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"must be a path without NUL characters; got {text!r}")
    return text


def existing_file(text: str) -> str:
    """An argparse ``type`` for a file that must exist (a YAML or JSON file the command reads):
    a missing one is reported by argparse under the option's name, before any work."""
    import os.path

    text = path_argument(text)
    if not os.path.isfile(text):
        what = "is a directory, not a file" if os.path.isdir(text) else "does not exist"
        raise argparse.ArgumentTypeError(f"{text!r} {what}: pass an existing file")
    return text


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` for the known name closest to a misspelt ``name``, or ``""``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def add_env_argument(parser: argparse.ArgumentParser) -> None:
    """``--env ID``: one of the registered ids, the default id by default."""
    from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

    parser.add_argument(
        "--env",
        default=DEFAULT_ENV_ID,
        choices=list(ENV_IDS),
        metavar="ID",
        help=f"env id (default {DEFAULT_ENV_ID}; one of {', '.join(ENV_IDS)})",
    )


def add_allow_other_id_argument(parser: argparse.ArgumentParser) -> None:
    """``--allow-other-id``: run trained policies on ids other than their own (with a warning)."""
    parser.add_argument(
        "--allow-other-id",
        action="store_true",
        help="run a trained policy on an id other than the one it was trained on (refused without it: ids of the "
        "same observation shape are different tasks); a warning names both ids",
    )


def _hyperparams(name: str) -> str:
    """The hyperparameter file ``name`` as the help texts name it: in the installed package
    (``tether_gym_agents/hyperparams/<name>``), or the checkout's ``agents/hyperparams/<name>``."""
    return f"{PACKAGE}/hyperparams/{name}"


def _docstring(command: str) -> str:
    """The docstring of the command's module, read from its source without importing it (the
    import is what is slow)."""
    source = (PACKAGE_DIR / f"{command}.py").read_text(encoding="utf-8")
    docstring = ast.get_docstring(ast.parse(source), clean=False)
    return docstring or ""


def _parser(command: str, epilog: str | None = None, text: str | None = None) -> argparse.ArgumentParser:
    return argparse.ArgumentParser(
        prog=program(command),
        description=text if text is not None else description(_docstring(command), command),
        epilog=epilog,
    )


def _training_arguments(parser: argparse.ArgumentParser, algo: str) -> None:
    """The options agents.train and agents.train_rllib share."""
    add_env_argument(parser)
    parser.add_argument(
        "--seed",
        type=int_at_least(0, MAX_TRAINING_SEED),
        default=0,
        help=f"seed of the model, the envs and the run directory, 0..{MAX_TRAINING_SEED} (default 0)",
    )
    parser.add_argument(
        "--multiagent",
        action="store_true",
        help="train one shared decentralised policy (every satellite its own agent, local observations); "
        f"hyperparameters from {_hyperparams(f'{algo}_multiagent.yml')} unless --hyperparams is given",
    )
    parser.add_argument(
        "--out",
        type=path_argument,
        default="runs",
        help=f"parent of the run directory <out>/<env>/{algo}_seed<seed> (default runs)",
    )


def train_parser() -> argparse.ArgumentParser:
    """``agents.train``."""
    parser = _parser(
        "train",
        epilog="Trust: runs are written as JSON + safetensors, which load without running code. "
        "--resume from an SB3 .zip/.pkl unpickles it, which runs any code a crafted file contains: "
        "it needs --trust-pickle.",
    )
    parser.add_argument(
        "--algo", default="ppo", choices=TRAIN_ALGORITHMS, help="SB3 algorithm (default ppo; one of ppo, sac, td3)"
    )
    _training_arguments(parser, "<algo>")
    parser.add_argument(
        "--timesteps",
        type=int_at_least(1),
        help="env steps to train for, instead of the file's n_timesteps; rounded up to whole rollouts "
        "(PPO: n_steps x n_envs), with a message when it is",
    )
    parser.add_argument(
        "--n-envs", type=int_at_least(1, MAX_NUM_ENVS), help="parallel envs, instead of the file's n_envs"
    )
    parser.add_argument(
        "--hyperparams",
        type=existing_file,
        help=f"YAML file instead of {_hyperparams('<algo>.yml')}, or a run's "
        "config.yml (reproduces that run's hyperparameters)",
    )
    parser.add_argument(
        "--resume",
        type=path_argument,
        help="checkpoint directory (or run directory, or best/) to continue training from",
    )
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help="allow --resume from a pickle-based SB3 .zip + .pkl (unpickling runs any code they hold)",
    )
    parser.add_argument(
        "--force", action="store_true", help="replace an earlier run with the same --out, env, algorithm and seed"
    )
    parser.add_argument(
        "--curriculum",
        nargs=2,
        type=float_between(0.0, 1.0),
        metavar=("START", "FRACTION"),
        help="raise the difficulty from START to 1 over the first FRACTION of the run",
    )
    parser.add_argument(
        "--eval-freq",
        type=int_at_least(1),
        default=50_000,
        help="env steps between evaluations (default 50000); a run shorter than that is evaluated once at its end",
    )
    parser.add_argument(
        "--eval-episodes",
        type=int_at_least(2, MAX_NUM_ENVS),
        default=32,
        help="evaluation episodes, the same seeds (1 000 000 up) at every evaluation (default 32; at least 2, "
        "for the interval of the paired difference)",
    )
    parser.add_argument(
        "--checkpoint-freq",
        type=int_at_least(1),
        default=250_000,
        help="env steps between checkpoints (default 250000)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (for logs)")
    parser.add_argument(
        "--verbose", type=int_at_least(0), default=0, help="SB3's verbosity: 0 quiet (default), 1 info, 2 debug"
    )
    return parser


def train_rllib_parser() -> argparse.ArgumentParser:
    """``agents.train_rllib``."""
    parser = _parser(
        "train_rllib",
        epilog='Needs the rllib extra (pip install "tether-gym[rllib]"). The policy is exported as JSON + '
        "safetensors, which load without running code; RLlib's checkpoints hold pickles, so --resume needs "
        "--trust-pickle.",
    )
    _training_arguments(parser, RLLIB_ALGO)
    parser.add_argument(
        "--timesteps",
        type=int_at_least(1),
        help="env steps to train for, instead of n_timesteps; RLlib trains whole iterations, so a few more may run "
        "(config.yml records how many did)",
    )
    parser.add_argument(
        "--num-env-runners", type=int_at_least(0), default=0, help="env runner processes (0: sample in the driver)"
    )
    parser.add_argument(
        "--envs-per-runner", type=int_at_least(1, MAX_NUM_ENVS), help="override num_envs_per_env_runner"
    )
    parser.add_argument(
        "--address", help="join the Ray cluster at HOST:PORT (or 'auto'); default: start a local Ray instance"
    )
    parser.add_argument("--num-cpus", type=int_at_least(1), help="CPUs of the local Ray instance (default: all)")
    parser.add_argument(
        "--hyperparams",
        type=existing_file,
        help=f"YAML file instead of {_hyperparams(f'{RLLIB_ALGO}.yml')}, or a run's config.yml",
    )
    parser.add_argument(
        "--resume",
        type=path_argument,
        help="RLlib checkpoint (<run>/checkpoints/iter_<n>) or run directory (its latest)",
    )
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help="allow --resume (RLlib checkpoints hold pickles, which can run code)",
    )
    parser.add_argument("--force", action="store_true", help="replace an earlier run with the same --out, env and seed")
    parser.add_argument(
        "--eval-freq", type=int_at_least(1), default=50_000, help="env steps between evaluations (default 50000)"
    )
    parser.add_argument(
        "--eval-episodes",
        type=int_at_least(2, MAX_NUM_ENVS),
        default=32,
        help="evaluation episodes (seeds 1 000 000 up; default 32; at least 2, for the paired difference's interval)",
    )
    parser.add_argument(
        "--checkpoint-freq",
        type=int_at_least(1),
        default=250_000,
        help="env steps between checkpoints (default 250000)",
    )
    return parser


def ars_parser() -> argparse.ArgumentParser:
    """``agents.ars``."""
    parser = _parser("ars")
    add_env_argument(parser)
    parser.add_argument(
        "--seed",
        type=int_at_least(0, 999),
        default=1,
        help="the run's seed, 0..999: it draws the perturbations and picks the training episodes (default 1)",
    )
    parser.add_argument(
        "--out",
        type=path_argument,
        default="runs",
        help="parent of the run directory <out>/<env>/ars_seed<seed> (default runs)",
    )
    parser.add_argument(
        "--hyperparams",
        type=existing_file,
        help=f"YAML file instead of {_hyperparams('ars.yml')}, or a run's config.yml (reproduces it)",
    )
    parser.add_argument("--iterations", type=int_at_least(1), help="ARS iterations, instead of the file's")
    parser.add_argument("--force", action="store_true", help="replace an earlier run with the same --out, env and seed")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (for logs)")
    return parser


def dagger_parser() -> argparse.ArgumentParser:
    """``agents.dagger``."""
    parser = _parser("dagger")
    add_env_argument(parser)
    parser.add_argument(
        "--seed",
        type=int_at_least(0, 999),
        default=1,
        help="the run's seed, 0..999: it initialises the network and picks the training episodes (default 1)",
    )
    parser.add_argument(
        "--out",
        type=path_argument,
        default="runs",
        help="parent of the run directory <out>/<env>/dagger_seed<seed> (default runs)",
    )
    parser.add_argument(
        "--hyperparams",
        type=existing_file,
        help=f"YAML file instead of {_hyperparams('dagger.yml')}, or a run's config.yml (reproduces it)",
    )
    parser.add_argument("--iterations", type=int_at_least(1), help="DAgger iterations, instead of the file's")
    parser.add_argument(
        "--episodes", type=int_at_least(1, MAX_NUM_ENVS), help="episodes per iteration, instead of the file's"
    )
    parser.add_argument("--force", action="store_true", help="replace an earlier run with the same --out, env and seed")
    parser.add_argument("--no-progress", action="store_true", help="no progress lines (only the summary)")
    return parser


def _controllers_trust_epilog() -> str:
    return (
        "Trust: shipped models and the runs of the training commands are JSON + safetensors and load without "
        "running code. A pickle-based SB3 model (.zip + vecnormalize.pkl) runs any code a crafted file contains "
        f"when loaded: it is refused unless --trust-pickle is given ({program('convert')} makes a safe copy)."
    )


def compare_parser() -> argparse.ArgumentParser:
    """``agents.compare``."""
    parser = _parser("compare", epilog=_controllers_trust_epilog())
    add_env_argument(parser)
    parser.add_argument(
        "--controllers",
        nargs="+",
        metavar="NAME",
        help="baseline names, mpc, shipped model names or policy directories "
        "(default: every baseline and every shipped model of the id)",
    )
    parser.add_argument(
        "--episodes",
        type=int_at_least(2, MAX_NUM_ENVS),
        default=64,
        help="held-out episodes per controller (default 64)",
    )
    parser.add_argument(
        "--seed", type=int_at_least(0), default=HELD_OUT_SEED, help=f"first held-out seed (default {HELD_OUT_SEED})"
    )
    parser.add_argument(
        "--satellite", type=int_at_least(0), default=0, help="satellite of the displacement plot (default 0)"
    )
    _add_report_arguments(parser, "comparison", "outputs/compare")
    return parser


def _add_report_arguments(parser: argparse.ArgumentParser, report: str, out: str) -> None:
    """The options compare and benchmark share: where the ``report`` goes, whether it replaces an
    earlier one and has plots, and which models of ``--controllers`` may load."""
    parser.add_argument("--out", type=path_argument, default=out, help=f"output directory (default {out})")
    parser.add_argument("--no-plots", action="store_true", help="write the tables only, no PNG plots (no matplotlib)")
    parser.add_argument("--force", action="store_true", help=f"replace an earlier {report} in --out")
    parser.add_argument(
        "--save-episodes",
        nargs="+",
        type=int_at_least(0),
        default=(),
        metavar="SEED",
        help="also record each controller's episode on these seeds, as --out/episodes/<id>/<controller>_seed<S>.npz, "
        "for tether-gym-view --recording (each is run again, one episode per controller and seed)",
    )
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help="allow pickle-based SB3 model paths in --controllers (unpickling runs any code they hold)",
    )
    add_allow_other_id_argument(parser)


def benchmark_parser() -> argparse.ArgumentParser:
    """``agents.benchmark``."""
    from tether_gym.registration import ENV_IDS

    parser = _parser(
        "benchmark",
        text="Every id of both tracks (standard and hard), every scripted baseline, the mpc reference and "
        "every shipped model on held-out seeds: mean returns, paired differences against the best scripted "
        "baseline, normalised scores (0 = passive, 100 = mpc), rliable's aggregate over the ids of each track, "
        "and every controller's excess cost over the shipped reference ceiling (read, not rerun).",
        epilog="Run time (2-core machine): the full run (every id, 64 episodes, mpc included) takes about "
        "2 h (the cost model's estimate: 39 min for the 8 massless standard ids, as measured, 25 min for each "
        "id with beaded tethers, most of it mpc; the 4-segment one took 8); it prints its own estimate before it "
        "starts. --quick takes about "
        "2-4 minutes. "
        "Trust: shipped models load without running code; a pickle-based SB3 model path in "
        "--controllers is refused unless --trust-pickle is given.",
    )
    parser.add_argument(
        "--envs",
        nargs="+",
        choices=list(ENV_IDS),
        metavar="ID",
        help=f"ids to run (default: every id of --track; all {len(ENV_IDS)}: {', '.join(ENV_IDS)})",
    )
    parser.add_argument(
        "--track",
        choices=["standard", "hard", "all"],
        default="all",
        help="the ids' track: standard (the ids a scripted law nearly solves), hard (tether_gym.registration."
        "HARD_TRACK: room left over the best law) or all (default); --envs must then name ids of it",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a smoke check of a few minutes: 8 held-out episodes (the reference ceiling's first seeds), every "
        "baseline and shipped model, no mpc (the ceiling and the reference scores hold the planner's numbers); "
        "noisier numbers, labelled as the quick mode in every output",
    )
    parser.add_argument(
        "--ceiling-file",
        type=path_argument,
        default=None,
        metavar="FILE",
        help="the reference ceiling's per-seed returns (default: the shipped ones, reference/ceiling.json in the "
        "package); the benchmark reads them, it does not rerun the planner",
    )
    parser.add_argument(
        "--controllers",
        nargs="+",
        metavar="NAME",
        help="baseline names, mpc, shipped model names or policy directories, run on every "
        "id that has them (a policy directory: on its own id, or on every id with --allow-other-id; "
        "default: every baseline, mpc and every shipped model of each id; passive is always added)",
    )
    parser.add_argument(
        "--episodes",
        type=int_at_least(2, MAX_NUM_ENVS),
        default=None,
        help="held-out episodes per controller and id (default 64; 8 with --quick)",
    )
    parser.add_argument(
        "--seed",
        type=int_at_least(0),
        default=HELD_OUT_SEED,
        help=f"first held-out seed (default {HELD_OUT_SEED}); also seeds the bootstrap",
    )
    parser.add_argument(
        "--reference",
        default=REFERENCE,
        help=f"the controller that scores 100 (default {REFERENCE}; another one anchors a "
        "different score, labelled as such)",
    )
    parser.add_argument(
        "--bootstrap-reps",
        type=int_at_least(100),
        default=50_000,
        help="bootstrap replications of the aggregate's intervals (default 50000, as in rliable)",
    )
    _add_report_arguments(parser, "benchmark", "outputs/benchmark")
    return parser


def ship_parser() -> argparse.ArgumentParser:
    """``agents.ship``."""
    parser = _parser("ship")
    parser.add_argument(
        "runs",
        nargs="+",
        type=path_argument,
        metavar="RUN",
        help=f"run directories of {program('train')} or {program('ars')}, or policy directories",
    )
    parser.add_argument(
        "--out",
        type=path_argument,
        default="agents/models",
        help="where shipped models go (default agents/models: the checkout's, when run from its root)",
    )
    parser.add_argument(
        "--episodes", type=int_at_least(2, MAX_NUM_ENVS), default=64, help="evaluation episodes (default 64)"
    )
    parser.add_argument("--force", action="store_true", help="replace shipped models")
    return parser


def convert_parser() -> argparse.ArgumentParser:
    """``agents.convert``."""
    parser = _parser(
        "convert", epilog="Converting unpickles SRC: a crafted SRC runs arbitrary code. Convert only files you trust."
    )
    parser.add_argument("source", metavar="SRC", type=path_argument, help="SB3 run directory or model .zip")
    parser.add_argument(
        "destination",
        metavar="DST",
        type=path_argument,
        help="directory for the safe format (may be SRC's directory)",
    )
    parser.add_argument(
        "--trust-pickle", action="store_true", help="required: SRC is unpickled, which runs any code it contains"
    )
    parser.add_argument("--best", action="store_true", help="convert SRC/best/best_model.zip")
    parser.add_argument("--algo", choices=TRAIN_ALGORITHMS, help="algorithm, if SRC has no config.yml")
    from tether_gym.registration import ENV_IDS

    parser.add_argument(
        "--env",
        metavar="ID",
        choices=list(ENV_IDS),
        help="env id the model was trained on, if SRC has no config.yml (recorded in DST)",
    )
    parser.add_argument("--training-state", action="store_true", help="keep the optimizer states (for --resume)")
    parser.add_argument(
        "--check-observations",
        type=int_at_least(16, MAX_CHECK_OBSERVATIONS),
        default=512,
        help="observations on which the actions must be bit-identical (default 512)",
    )
    parser.add_argument(
        "--reference", action="store_true", help=f"keep those observations and actions in DST/{REFERENCE_FILE}"
    )
    parser.add_argument("--force", action="store_true", help="replace an earlier conversion in DST")
    return parser


_PARSERS: dict[str, Callable[[], argparse.ArgumentParser]] = {
    "train": train_parser,
    "compare": compare_parser,
    "benchmark": benchmark_parser,
    "ship": ship_parser,
    "convert": convert_parser,
    "train_rllib": train_rllib_parser,
    "ars": ars_parser,
    "dagger": dagger_parser,
}


ConfigT = TypeVar("ConfigT")


def config_from_args(config_class: type[ConfigT], args: argparse.Namespace, **given: Any) -> ConfigT:
    """A command's config (a dataclass, ``config_class``) from its parsed command line ``args``:
    each field is ``given[field]`` if given, else the option of the same name, else the field's
    default. An option named otherwise than its field (``--env`` for ``env_id``, ``--no-plots``
    for ``plots``) is passed in ``given``."""
    names = [field.name for field in dataclasses.fields(config_class)]  # type: ignore[arg-type]
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise TypeError(f"{config_class.__name__} has no field {', '.join(unknown)}")
    values = {
        name: given[name] if name in given else getattr(args, name)
        for name in names
        if name in given or hasattr(args, name)
    }
    return config_class(**values)


def parse_before_imports(command: str) -> None:
    """Parse the command line (``sys.argv``) with ``command``'s parser and drop the result: argparse
    exits for ``--help`` and for bad arguments. A command module run as ``__main__`` calls it
    before its slow imports, so that ``python -m agents.<command> --help`` answers at once."""
    build_parser(command).parse_args(sys.argv[1:])


def build_parser(command: str) -> argparse.ArgumentParser:
    """The argument parser of ``command`` (a key of :data:`agents.common.commands.SCRIPTS`: every one
    has a parser here, which a test checks)."""
    if command not in _PARSERS:
        raise ValueError(f"unknown command {command!r}: expected one of {', '.join(_PARSERS)}")
    return _PARSERS[command]()
