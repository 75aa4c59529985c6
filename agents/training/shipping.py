"""Shipping trained models: the library part of ``python -m agents.ship`` (:func:`ship`).

Each run given is a run directory of a trainer (its ``best/`` policy is the candidate), or a
policy directory (a checkpoint, or a model shipped earlier). Every candidate is rolled out on the
evaluation seeds (:func:`agents.training.selection.evaluation_seeds`, 1 000 000 up), the seeds training
selected its ``best/`` on, alongside every scripted baseline (:func:`evaluate_candidates`). Per id
and algorithm (:func:`model_name`), the candidate with the highest mean return there is shipped:
its policy files, ``config.yml`` and training log are copied to ``OUT/<id>/<algo>/`` with reference
actions and a fresh ``MANIFEST.sha256``. The held-out seeds the benchmark reports (10 000 up) play
no part in the choice.

Every candidate's result goes to ``OUT/training_runs.json`` and ``OUT/training_runs.md``, with the
command that reproduces each shipped model (:func:`reproduce_command`); entries of earlier calls
for other ids or algorithms are kept, so runs can be shipped id by id.
"""

from __future__ import annotations

import hashlib
import json
import shlex
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.cli import REFERENCE_FILE
from ..common.commands import program
from ..common.files import (
    OutputError,
    atomic_directory,
    atomic_write_bytes,
    atomic_write_text,
    check_no_symlinks_between,
    check_output_files,
    holds_output_claims,
    make_dirs_below,
    prepare_output_dir,
)
from ..common.reading import read_bounded, read_yaml
from ..policies.codecs import MAX_JSON_BYTES, parse_json
from ..policies.format import POLICY_HOSTS, is_policy_dir, read_metadata, write_manifest
from ..policies.layout import MANIFEST_FILE, METADATA_FILE, NORMALIZATION_FILE, WEIGHTS_FILE, PolicyFormatError
from .selection import EVALUATIONS_FILE, baseline_returns, episode_returns, evaluation_seeds

__all__ = [
    "MULTIAGENT_SUFFIX",
    "RUNS_TABLE",
    "SHIPPED_FILES",
    "RunFileError",
    "evaluate_candidates",
    "model_name",
    "read_runs_table",
    "reproduce_command",
    "ship",
]

SHIPPED_FILES = (METADATA_FILE, WEIGHTS_FILE, NORMALIZATION_FILE)
RUNS_TABLE = "training_runs"
#: Every file ship writes into a shipped model's directory: the only ones it ever replaces there.
INSTALLED_FILES = (*SHIPPED_FILES, "config.yml", EVALUATIONS_FILE, REFERENCE_FILE, MANIFEST_FILE)


class RunFileError(ValueError):
    """A file ship reads (a run's ``config.yml`` or ``best/evaluations.json``, or the runs table
    ``training_runs.json`` it merges into) that does not hold what ship needs; the message names
    the file, the key and the fix. Raised before any rollout."""


#: What a shared decentralised policy's model name adds to its algorithm's (``ppo_multiagent``),
#: as agents.train names its run directories: the two kinds of model of an id ship side by side.
MULTIAGENT_SUFFIX = "_multiagent"


def model_name(metadata: Mapping[str, Any]) -> str:
    """The name a policy ships under: its algorithm, with :data:`MULTIAGENT_SUFFIX` for a shared
    decentralised policy."""
    return metadata["algo"] + (MULTIAGENT_SUFFIX if metadata.get("multiagent") is not None else "")


def _policy_dir(run: Path) -> Path:
    for directory in (run / "best", run):
        if is_policy_dir(directory):
            return directory
    raise FileNotFoundError(f"{run} holds no policy (neither {run}/best/{METADATA_FILE} nor {run}/{METADATA_FILE})")


def _number_or_none(value: Any) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value))


def _require(condition: bool, path: Path, key: str, expected: str, value: Any) -> None:
    if not condition:
        raise RunFileError(
            f"{path}: {key} must be {expected}; got {value!r}: restore the file from its run, or leave that run out"
        )


def _check_first_beat(path: Path, key: str, first_beat: Any) -> None:
    _require(first_beat is None or isinstance(first_beat, dict), path, key, "an object or null", first_beat)
    for name, found in (first_beat or {}).items():
        where = f"{key}.{name}"
        if found is None:
            continue
        _require(isinstance(found, dict), path, where, "an object or null", found)
        for field in ("wall_time_s", "timesteps"):
            value = found.get(field)
            _require(value is not None and _number_or_none(value), path, f"{where}.{field}", "a finite number", value)


def _training_log(run: Path, policy_dir: Path) -> dict[str, Any] | None:
    """The run's evaluation log (``evaluations.json``), checked for the keys ship reads."""
    for path in (policy_dir / EVALUATIONS_FILE, run / "best" / EVALUATIONS_FILE):
        if path.is_file():
            try:
                log = parse_json(read_bounded(path, MAX_JSON_BYTES, RunFileError, "restore it from its run"), path)
            except PolicyFormatError as error:
                raise RunFileError(str(error)) from error
            _require(isinstance(log, dict), path, "the file", "a JSON object", type(log).__name__)
            training = log.get("training")
            _require(training is None or isinstance(training, dict), path, "training", "an object or null", training)
            wall = (training or {}).get("wall_time_s")
            _require(_number_or_none(wall), path, "training.wall_time_s", "a finite number or null", wall)
            _check_first_beat(path, "first_beat", log.get("first_beat"))
            return log
    return None


def _config(run: Path, policy_dir: Path) -> dict[str, Any]:
    """The run's ``config.yml`` (safe YAML), checked for the keys ship reads (``seed``, ``command``)."""
    for path in (policy_dir / "config.yml", run / "config.yml"):
        if path.is_file():
            config = read_yaml(path, RunFileError) or {}
            _require(isinstance(config, dict), path, "the file", "a mapping", type(config).__name__)
            seed = config.get("seed")
            _require(
                seed is None or (isinstance(seed, int) and not isinstance(seed, bool)), path, "seed", "an integer", seed
            )
            command = config.get("command")
            _require(command is None or isinstance(command, str), path, "command", "a string", command)
            if isinstance(command, str):
                try:
                    shlex.split(command)
                except ValueError as error:
                    raise RunFileError(f"{path}: command is not a shell command line ({error}): {command!r}") from None
            return config
    return {}


#: The keys of a runs-table entry, and what each must be ("number": finite; "text": a string).
_ENTRY_KEYS = {
    "env_id": "text",
    "algo": "text",
    "timesteps": "number",
    "mean_return": "number",
    "bar": "text",
    "bar_mean_return": "number",
    "difference": "number",
    "difference_low": "number",
    "difference_high": "number",
}


def read_runs_table(out: Path) -> list[dict[str, Any]]:
    """The entries of ``out/training_runs.json`` (none when it is absent), checked for everything
    the merged table is written from: a malformed file is refused (:class:`RunFileError`, naming
    the file, the entry and the key) before any rollout, not after them."""
    table = out / f"{RUNS_TABLE}.json"
    if not table.is_file():
        return []
    try:
        data = parse_json(read_bounded(table, MAX_JSON_BYTES, RunFileError, "restore it from git"), table)
    except PolicyFormatError as error:
        raise RunFileError(f"{error} (or move it away: ship then starts a new table)") from error
    _require(isinstance(data, dict) and isinstance(data.get("runs"), list), table, "runs", "a list", data)
    entries = data["runs"]
    for index, entry in enumerate(entries):
        where = f"runs[{index}]"
        _require(isinstance(entry, dict), table, where, "an object", entry)
        for key, kind in _ENTRY_KEYS.items():
            value = entry.get(key)
            good = isinstance(value, str) if kind == "text" else value is not None and _number_or_none(value)
            _require(good, table, f"{where}.{key}", "a string" if kind == "text" else "a finite number", value)
        _require(
            _number_or_none(entry.get("wall_time_s")),
            table,
            f"{where}.wall_time_s",
            "a number or null",
            entry.get("wall_time_s"),
        )
        seeds = entry.get("seeds")
        _require(
            isinstance(seeds, list) and len(seeds) == 2 and all(isinstance(v, int) for v in seeds),
            table,
            f"{where}.seeds",
            "a list of two integers",
            seeds,
        )
        _require(
            isinstance(entry.get("shipped"), bool), table, f"{where}.shipped", "true or false", entry.get("shipped")
        )
        for key in ("residual_on", "command", "reproduce"):
            value = entry.get(key)
            _require(value is None or isinstance(value, str), table, f"{where}.{key}", "a string or null", value)
        _check_first_beat(table, f"{where}.first_beat", entry.get("first_beat"))
    return entries


def _check_run(run: Path) -> tuple[Path, dict[str, Any], dict[str, Any], dict[str, Any] | None]:
    """What ship reads of ``run``, checked before any rollout: its policy directory and metadata
    (with an env id), its ``config.yml`` and its evaluation log."""
    policy_dir = _policy_dir(run)
    metadata = read_metadata(policy_dir)
    if metadata["env_id"] is None:
        raise PolicyFormatError(f"{policy_dir}/{METADATA_FILE} names no env id: it cannot be shipped for one")
    return policy_dir, metadata, _config(run, policy_dir), _training_log(run, policy_dir)


def evaluate_candidates(runs: Sequence[str | Path], episodes: int = 64) -> list[dict[str, Any]]:
    """Roll every candidate of ``runs`` and every scripted baseline of its id out on the
    evaluation seeds; returns one record (plain JSON data) per run."""
    import gymnasium as gym

    from ..evaluation.stats import paired_difference
    from ..policies import TrainedPolicy

    seeds = evaluation_seeds(episodes)
    baselines: dict[str, tuple[dict[str, np.ndarray], str]] = {}
    candidates = []
    weights_seen: set[str] = set()
    for run in map(Path, runs):
        policy_dir, metadata, config, log = _check_run(run)
        # A shipped model passed beside the run it came from is one candidate, not two.
        weights = hashlib.sha256((policy_dir / WEIGHTS_FILE).read_bytes()).hexdigest()
        if weights in weights_seen:
            continue
        weights_seen.add(weights)
        env_id = metadata["env_id"]
        if env_id not in baselines:
            baselines[env_id] = baseline_returns(env_id, seeds)
        by_name, bar = baselines[env_id]
        policy = TrainedPolicy(policy_dir)
        env = gym.make(env_id)
        policy.attach(env)
        env.close()
        returns = episode_returns(policy, env_id, seeds)
        paired = paired_difference(returns, by_name[bar])
        training = (log or {}).get("training") or {}
        candidates.append(
            {
                "env_id": env_id,
                "algo": model_name(metadata),
                "run": str(run),
                "policy": str(policy_dir),
                "seed": config.get("seed"),
                "command": config.get("command"),
                "timesteps": metadata["num_timesteps"],
                "wall_time_s": training.get("wall_time_s"),
                "residual_on": metadata.get("residual_on"),
                "mean_return": float(returns.mean()),
                "bar": bar,
                "bar_mean_return": float(by_name[bar].mean()),
                "difference": paired.mean,
                "difference_low": paired.low,
                "difference_high": paired.high,
                "baselines": {name: float(r.mean()) for name, r in by_name.items()},
                "first_beat": (log or {}).get("first_beat"),
                "seeds": [seeds[0], seeds[-1]],
            }
        )
    return candidates


def _write_reference_actions(directory: Path, env_id: str, count: int = 1024) -> None:
    """``reference_actions.safetensors``: observations (along the policy's own trajectories, seeds
    0-7, and drawn around its normalisation statistics) and the network's deterministic actions on
    them, so that a test can tell, on any machine, that the shipped files still act as shipped."""
    import gymnasium as gym
    import torch

    from ..common.cli import REFERENCE_FILE
    from ..policies import TrainedPolicy
    from ..policies.format import tensor_bytes
    from ..policies.reference import reference_observations, safe_actions, trajectory_observations

    policy = TrainedPolicy(directory)
    env = gym.make(env_id)
    policy.attach(env)
    env.close()
    statistics = policy.normalizer
    mean, var = (statistics.obs_mean, statistics.obs_var) if statistics is not None else (0.0, 1.0)
    if policy.multiagent is not None:  # a shared decentralised policy: the agents' local observations
        from ..controllers.decentralised import local_trajectory_observations

        trajectory = local_trajectory_observations(policy.act_local, env_id, policy.multiagent)
    else:
        trajectory = trajectory_observations(lambda obs: policy.predict(obs)[0], env_id)
    observations = reference_observations(
        count, policy.policy.observation_space, mean, var, np.random.default_rng(0), trajectory
    )
    actions = safe_actions(directory, observations)
    atomic_write_bytes(
        directory / REFERENCE_FILE,
        tensor_bytes(
            {"observations": torch.from_numpy(observations), "actions": torch.from_numpy(np.asarray(actions))},
            metadata={"pipeline": "normalization.json, then the policy's predict(deterministic=True)"},
        ),
    )


def _markdown(entries: list[dict[str, Any]]) -> str:
    lines = [
        "# Training runs and the shipped models",
        "",
        (
            "Every training run considered for shipping, evaluated on the evaluation seeds "
            f"({entries[0]['seeds'][0]}..{entries[0]['seeds'][1]}, never the benchmark's held-out seeds). "
            "Δ: paired difference of the mean return from the id's best scripted baseline on those seeds (95 % t "
            "interval). Beat: wall time from the start of the training command to the first evaluation whose "
            f"mean return beat that baseline's (— never). Made by `{program('ship')}`."
        ),
        "",
    ]
    columns = ["id", "algo", "seed", "steps", "wall time", "mean return", "best baseline", "Δ vs best baseline"]
    columns += ["beat velocity feedback", "beat best baseline", "shipped"]
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]

    def beat(entry: dict[str, Any], name: str) -> str:
        found = (entry.get("first_beat") or {}).get(name)
        return "—" if not found else f"{found['wall_time_s'] / 60:.1f} min ({found['timesteps'] / 1e6:.2f} M)"

    for entry in sorted(entries, key=lambda e: (e["env_id"], e["algo"], str(e["seed"]))):
        wall = "?" if entry["wall_time_s"] is None else f"{entry['wall_time_s'] / 60:.1f} min"
        algo = entry["algo"] + (f" (residual on {entry['residual_on']})" if entry["residual_on"] else "")
        shipped = "**yes**" if entry["shipped"] else ""
        lines.append(
            f"| {entry['env_id']} | {algo} "
            f"| {entry['seed']} | {entry['timesteps'] / 1e6:.2f} M | {wall} | {entry['mean_return']:.2f} "
            f"| {entry['bar']} {entry['bar_mean_return']:.2f} "
            f"| {entry['difference']:+.2f} [{entry['difference_low']:+.2f}, {entry['difference_high']:+.2f}] "
            f"| {beat(entry, 'velocity_feedback')} | {beat(entry, entry['bar'])} | {shipped} |"
        )
    lines += [
        "",
        "## Shipped models (the command that reproduces each)",
        "",
        "| id | algo | seed | steps | wall time | command |",
        "|---|---|---|---|---|---|",
    ]
    for entry in sorted((e for e in entries if e["shipped"]), key=lambda e: (e["env_id"], e["algo"])):
        wall = "?" if entry["wall_time_s"] is None else f"{entry['wall_time_s'] / 60:.1f} min"
        lines.append(
            f"| {entry['env_id']} | {entry['algo']} | {entry['seed']} | {entry['timesteps'] / 1e6:.2f} M "
            f"| {wall} | `{entry.get('reproduce') or entry['command']}` |"
        )
    return "\n".join(lines) + "\n"


def reproduce_command(candidate: Mapping[str, Any], shipped_at: str) -> str:
    """The training command that reproduces a shipped model: the run's own command (its evaluation
    and checkpoint settings choose ``best/``), with the hyperparameters read from the shipped
    ``config.yml``, so that the command stays true when the YAML files are retuned."""
    env_id, algo = candidate["env_id"], candidate["algo"]
    tokens = shlex.split(candidate.get("command") or program("train"))
    kept: list[str] = []
    skip_value = False
    for token in tokens:
        if skip_value:
            skip_value = False
        elif token == "--hyperparams":
            skip_value = True
        elif not token.startswith("--hyperparams="):
            kept.append(token)
    algorithm = algo.removesuffix(MULTIAGENT_SUFFIX)
    # agents.train takes --algo; a trainer of its own (agents.ars) is named by its command.
    flags = [("--env", env_id), ("--seed", candidate["seed"])]
    if algorithm not in POLICY_HOSTS:
        flags.insert(0, ("--algo", algorithm))
    for flag, value in flags:
        if flag not in kept:
            kept += [flag, str(value)]
    return shlex.join([*kept, "--hyperparams", str(Path(shipped_at) / env_id / algo / "config.yml")])


@holds_output_claims
def ship(
    runs: Sequence[str | Path], out: str | Path, episodes: int = 64, force: bool = False, command: str | None = None
) -> list[dict[str, Any]]:
    """Evaluate ``runs``, ship the best per id and algorithm into ``out`` (see the module
    docstring) and return every candidate's record (with ``shipped``).

    Before any rollout it checks every output and every file it reads: ``out`` (usable, claimed
    against a second command), the runs table it merges into (:func:`read_runs_table`), each
    run's files, and each target directory ``out/<id>/<algo>`` (no symlink on the way, nothing
    there that ship does not write, and no shipped model unless ``force``). An existing shipped
    model is replaced only with ``force``; to keep it in the running, pass its directory among
    ``runs``. A model is installed as a whole (a new directory renamed into place)."""
    # The episodes run as one batch: more than the largest vector env failed after the checks.
    episodes = check_int("episodes", episodes, 2, MAX_NUM_ENVS)
    shipped_at = str(out)
    root = Path(out)
    out = prepare_output_dir(out, argument="--out")
    check_output_files(out, (f"{RUNS_TABLE}.json", f"{RUNS_TABLE}.md"), force=True, argument="--out")
    read_runs_table(out)
    keys: dict[tuple[str, str], list[Path]] = {}
    for run in map(Path, runs):
        policy_dir, metadata, _, _ = _check_run(run)
        keys.setdefault((metadata["env_id"], model_name(metadata)), []).append(policy_dir.resolve())
    for (env_id, algo), sources in keys.items():
        _check_target(root, out / env_id / algo, force, sources)
    candidates = evaluate_candidates(runs, episodes)
    chosen = _best_per_id_and_algo(candidates)
    for (env_id, algo), candidate in chosen.items():
        target = out / env_id / algo
        if (target / METADATA_FILE).exists() and not force and Path(candidate["policy"]).resolve() != target.resolve():
            raise OutputError(
                f"{target} already holds a shipped model, which {candidate['policy']} beat: pass --force to replace it"
            )
    for candidate in candidates:
        candidate["shipped"] = chosen[(candidate["env_id"], candidate["algo"])] is candidate
        if candidate["shipped"]:
            candidate["reproduce"] = reproduce_command(candidate, shipped_at)
    for (env_id, algo), candidate in chosen.items():
        make_dirs_below(root, out / env_id)
        _install(candidate, out / env_id / algo, env_id)
    _write_runs_table(out, candidates, command)
    for candidate in candidates:
        print(
            f"{candidate['env_id']} {candidate['algo']} seed {candidate['seed']}: {candidate['mean_return']:.2f} "
            f"(vs {candidate['bar']} {candidate['difference']:+.2f} [{candidate['difference_low']:+.2f}, "
            f"{candidate['difference_high']:+.2f}]){'  <- shipped' if candidate['shipped'] else ''}"
        )
    return candidates


def _check_target(root: Path, target: Path, force: bool, sources: Sequence[Path]) -> None:
    """Refuse, before any rollout, a target directory ship must not write: one reached through a
    symlink below ``--out``, a file, one holding files ship does not write (never deleted, with
    ``force`` too), or a shipped model without ``force`` when no candidate of ``sources`` is it."""
    check_no_symlinks_between(root, target)
    if target.exists() and not target.is_dir():
        raise OutputError(f"{target} is a file where a shipped model's directory goes: move it away")
    if not target.is_dir():
        return
    foreign = sorted(p.name for p in target.iterdir() if p.name not in INSTALLED_FILES or not p.is_file())
    if foreign:
        raise OutputError(
            f"{target} holds {', '.join(foreign)}, which ship does not write: move "
            f"{'them' if len(foreign) > 1 else 'it'} away (ship never deletes files it did not write, "
            "with --force too)"
        )
    if (target / METADATA_FILE).exists() and not force and target.resolve() not in sources:
        raise OutputError(
            f"{target} already holds a shipped model: pass --force to replace it, or pass {target} among the runs "
            "to keep it in the running"
        )


def _best_per_id_and_algo(candidates: Sequence[dict[str, Any]]) -> dict[tuple[str, str], dict[str, Any]]:
    """The candidate with the highest mean return for each (env id, algorithm); the first on ties."""
    chosen: dict[tuple[str, str], dict[str, Any]] = {}
    for candidate in candidates:
        key = (candidate["env_id"], candidate["algo"])
        if key not in chosen or candidate["mean_return"] > chosen[key]["mean_return"]:
            chosen[key] = candidate
    return chosen


def _install(candidate: Mapping[str, Any], target: Path, env_id: str) -> None:
    """Copy ``candidate``'s policy, its run's ``config.yml`` and evaluations, reference actions of
    ``env_id`` and a checksum manifest into ``target``, as a whole: the files are written into a
    new directory beside it, which then replaces it (:func:`agents.common.files.atomic_directory`),
    so a failure or interrupt leaves the earlier shipped model whole. Nothing happens when the
    candidate is ``target``."""
    source = Path(candidate["policy"])
    if source.resolve() == target.resolve():
        return
    run = Path(candidate["run"])
    with atomic_directory(target, ours=INSTALLED_FILES, others="refuse") as staging:
        for name in SHIPPED_FILES:
            if (source / name).is_file():
                shutil.copy2(source / name, staging / name)
        for name, origin in (("config.yml", run / "config.yml"), (EVALUATIONS_FILE, run / "best" / EVALUATIONS_FILE)):
            if origin.is_file():
                shutil.copy2(origin, staging / name)
        write_manifest(staging, [p.name for p in staging.iterdir()])  # loading inside agents/models needs it
        _write_reference_actions(staging, env_id)
        write_manifest(staging, [p.name for p in staging.iterdir()])


def _write_runs_table(out: Path, candidates: Sequence[dict[str, Any]], command: str | None) -> None:
    """Merge ``candidates`` into the runs table in ``out`` (JSON and Markdown): they replace the
    earlier entries of every (env id, algorithm) they cover."""
    table = out / f"{RUNS_TABLE}.json"
    earlier = read_runs_table(out)
    replaced = {(c["env_id"], c["algo"]) for c in candidates}
    entries = [e for e in earlier if (e["env_id"], e["algo"]) not in replaced] + list(candidates)
    atomic_write_text(table, json.dumps({"command": command, "runs": entries}, indent=1) + "\n")
    atomic_write_text(out / f"{RUNS_TABLE}.md", _markdown(entries))
