"""The safe policy format: trained policies stored as data that cannot run code when loaded.

A *policy directory* holds:

* ``policy.json``: metadata (JSON) -- the algorithm, env id, SB3 policy alias (``MlpPolicy``),
  the policy's constructor keyword arguments (``net_arch``, activation *name*, ``log_std_init``,
  ...), the observation and action spaces (shapes, dtypes and bounds), the number of timesteps
  trained, how the outputs become actions (:class:`~.spec.PolicySpec`: ``residual_on``,
  ``multiagent``), the library versions and the provenance (seed, training command, source files);
* ``policy.safetensors``: the policy network's ``state_dict`` (safetensors: a JSON header and
  raw tensor bytes, nothing executable);
* ``normalization.json``: the ``VecNormalize`` statistics (observation mean/var/count, return
  statistics, ``clip_obs``, ``epsilon``, flags), when the policy was trained with them
  (:mod:`.normalization`);
* ``training.safetensors`` + ``training.json`` (optional): the optimizer states and counters
  needed to resume training (``python -m agents.train --resume DIR``; :mod:`.sb3_state`);
* ``MANIFEST.sha256``: the SHA-256 of every other file, ``sha256sum`` format.

The file names, the format's name and version and its errors are in :mod:`.layout`; the JSON,
space and class-name codecs in :mod:`.codecs`.

Loading (:func:`load_policy`) reads only JSON, ``sha256`` text and safetensors. It builds the SB3
policy object from the metadata: the class comes from the algorithm's own alias table, every
class-valued keyword argument (activation, feature extractor, optimizer) from a fixed table of
names, so the files cannot name arbitrary code. Before it builds anything, it bounds what the
files may cost: each file's size, and the network's parameter count computed from ``policy.json``
alone (:mod:`.size`), which must match the weights file's. It then loads the weights with
``load_state_dict(strict=True)``. Nothing here imports :mod:`pickle`: the pickle-based SB3 files
are handled, behind an explicit opt-in, by :mod:`agents.policies.pickled`.

Each file is read once into memory; its checksum is verified on those bytes and the same bytes
are parsed, so a file cannot change between the check and the load.

Why the format describes an SB3 policy, and what its next version changes
-------------------------------------------------------------------------
What version 1 is: a *recipe for an SB3 policy object*. ``policy.json`` names an SB3 policy class
(the algorithm's alias, ``MlpPolicy``) and its constructor arguments; ``policy.safetensors`` is
that object's ``state_dict``, under SB3's parameter names (``mlp_extractor.policy_net.0.weight``,
``action_net.weight``, ``log_std``, ...). What the network computes -- the layers, the order of
the float operations, how a Gaussian mean is clipped or a squashed output rescaled into the
action bounds -- is not in the files: it is SB3's code at the loader's version. That is also why
the shipped models act to the bit as they did in training: the loader runs the very code path
(``policy.predict(obs, deterministic=True)`` after the normaliser) that produced the reference
actions.

Policies that other trainers make are stored inside an SB3 "vessel": ARS's linear policy is the
actor of a PPO ``ActorCriticPolicy`` with ``net_arch: {pi: [], vf: []}`` (``algo: ars``, through
:data:`POLICY_HOSTS`), and an RLlib module is copied parameter by parameter into a PPO
``MlpPolicy`` of the same shape (``algo: ppo``, ``provenance.trainer: rllib``). What the vessel
costs:

* every reader needs SB3 (and torch) installed, even for a linear map, and a file is only as
  stable as SB3's class layout and parameter names: an SB3 release that renames a layer or
  changes how ``predict`` post-processes actions breaks or silently changes every file;
* a foreign policy carries parts it does not have: ARS's files hold a value head of zeros and an
  unused ``log_std``, and the ``algo`` field mixes who trained a policy with which SB3 class
  rebuilds it;
* a policy SB3 cannot express (another layer layout, a recurrent or distilled network) cannot be
  stored at all, and each new trainer writes its own adapter into the vessel (RLlib's
  parameter-name mapping, the exact normaliser divisor), checked bit for bit by hand.

The choice: version 1 stays what it is -- its bytes are fixed (training with a seed writes the
same files) and the shipped models must load to the bit, which only the SB3 code path guarantees
for them -- and the format's next version describes the network on its own terms. It is worth
its cost once a policy arrives that SB3 cannot hold (the distilled policies planned), not before:
until then the vessel's cost is bounded and its bit-exactness is free. Version 2 would change:

* ``policy.json`` gets a ``network`` entry: the layers in order (linear with its input and output
  sizes and tensor names, activation by name from :data:`.codecs.ACTIVATIONS`), and the action
  head (a deterministic mean clipped to the action bounds, or a tanh squash rescaled to them);
  ``policy``/``policy_kwargs`` go, ``algo`` becomes provenance (the trainer), not a class lookup;
* ``policy.safetensors`` names tensors by that description (``layers.0.weight``), not by SB3;
* loading builds a small torch module from the description, without SB3, with the float
  operations in SB3's order so that version-1 models converted to it act to the bit (checked
  against each shipped model's ``reference_actions.safetensors``); SB3 stays one saver (its
  policy described as layers) and, for ``--resume``, one loader: the training state
  (:mod:`.sb3_state`) remains SB3's, as only SB3 resumes it;
* a reader dispatches on ``format_version``, so version-1 directories keep loading as now.

The modules are cut so that version 2 adds a describer and a builder here and a layer codec in
:mod:`.codecs`: the normalisation statistics (:mod:`.normalization`), the manifest and the
residual and multi-agent settings (:mod:`.spec`) do not depend on SB3 and carry over unchanged.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra, require

from ..common.commands import program
from ..common.files import atomic_write_bytes, atomic_write_text
from ..common.reading import read_bounded
from ..common.versions import POLICY_PACKAGES, package_versions
from .codecs import (
    MAX_JSON_BYTES,
    check_action_bounds,
    decode_policy_kwargs,
    decode_space,
    dump_json,
    encode_policy_kwargs,
    encode_space,
    json_value,
    parse_json,
    require_entry,
)
from .layout import (
    FORMAT,
    FORMAT_VERSION,
    MANIFEST_FILE,
    METADATA_FILE,
    NORMALIZATION_FILE,
    TRAINING_META_FILE,
    TRAINING_STATE_FILE,
    WEIGHTS_FILE,
    ChecksumError,
    PolicyFormatError,
)
from .normalization import NormalizationStatistics
from .sb3_state import TRAINING_STATE_FORMAT, capture_training_state, check_training_state
from .size import MAX_TENSOR_FILE_BYTES, parameter_count
from .spec import PolicySpec

with needs_extra("train", "the policy files"):
    import torch
    from stable_baselines3 import PPO, SAC, TD3
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import BasePolicy
    from stable_baselines3.common.vec_env import VecNormalize

__all__ = [
    "ALGORITHMS",
    "POLICY_HOSTS",
    "LoadedPolicy",
    "check_resumable",
    "is_policy_dir",
    "load_policy",
    "load_tensors",
    "load_training_state",
    "policy_alias",
    "policy_constructor_kwargs",
    "policy_metadata",
    "read_manifest",
    "read_metadata",
    "save_policy",
    "sha256_hex",
    "tensor_bytes",
    "verify_manifest",
    "write_manifest",
]

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}
#: Training algorithms that are not SB3's, and the SB3 algorithm whose policy classes store their
#: policies: ARS (:mod:`agents.ars`) trains the linear actor of PPO's ``ActorCriticPolicy``, and
#: DAgger (:mod:`agents.dagger`) its MLP actor.
POLICY_HOSTS: dict[str, type[BaseAlgorithm]] = {"ars": PPO, "dagger": PPO}
#: The largest manifest read, bytes: one line of 67 bytes and a name per file of the directory.
MAX_MANIFEST_BYTES = 64 * 2**10
_SHA256_LINE = re.compile(r"^([0-9a-f]{64})  ([^/\\\x00]+)$")


def _safetensors() -> Any:
    """The ``safetensors.torch`` module, with an install hint when it is missing."""
    return require("safetensors.torch", "train", "the policy files (stored as safetensors)")


# ---------------------------------------------------------------------------------------------
# SB3 policy classes
# ---------------------------------------------------------------------------------------------


def policy_constructor_kwargs(model: BaseAlgorithm) -> dict[str, Any]:
    """The keyword arguments ``model`` built its policy with (besides the spaces and the learning
    rate schedule): its ``policy_kwargs``, plus ``use_sde``, which on-policy algorithms pass
    separately."""
    kwargs = dict(model.policy_kwargs)
    if isinstance(model, OnPolicyAlgorithm):
        kwargs["use_sde"] = model.use_sde
    return kwargs


def _policy_class(algo: str, alias: str, where: str) -> type[BasePolicy]:
    hosts = {**ALGORITHMS, **POLICY_HOSTS}
    if algo not in hosts:
        raise PolicyFormatError(f"{where}: algorithm {algo!r} is not one of {sorted(hosts)}")
    aliases = hosts[algo].policy_aliases
    if alias not in aliases:
        raise PolicyFormatError(f"{where}: policy {alias!r} is not one of {algo}'s {sorted(aliases)}")
    return aliases[alias]


def policy_alias(model: BaseAlgorithm) -> str:
    """The name (``MlpPolicy``, ...) under which ``model``'s algorithm knows its policy class."""
    for alias, cls in model.policy_aliases.items():
        if cls is model.policy_class:
            return alias
    raise PolicyFormatError(
        f"policy class {model.policy_class.__name__} is not one of {type(model).__name__}'s named policies "
        f"{sorted(model.policy_aliases)}: the policy format can store only those"
    )


def _algo_name(model: BaseAlgorithm) -> str:
    for name, cls in ALGORITHMS.items():
        if type(model) is cls:
            return name
    raise PolicyFormatError(f"{type(model).__name__} is not one of the algorithms {sorted(ALGORITHMS)}")


def _constant_schedule(_: float) -> float:
    """The learning rate of a policy loaded for inference: never used."""
    return 0.0


# ---------------------------------------------------------------------------------------------
# Checksums
# ---------------------------------------------------------------------------------------------


def sha256_hex(data: bytes) -> str:
    """The SHA-256 of ``data`` as 64 lowercase hex digits (as ``sha256sum`` writes it)."""
    return hashlib.sha256(data).hexdigest()


def write_manifest(directory: Path, names: Iterable[str]) -> None:
    """Write ``MANIFEST.sha256`` (``sha256sum`` format, sorted) for ``names`` in ``directory``
    (the manifest itself is never listed: its own hash cannot be in it)."""
    lines = [f"{sha256_hex((directory / name).read_bytes())}  {name}" for name in sorted(set(names) - {MANIFEST_FILE})]
    atomic_write_text(directory / MANIFEST_FILE, "\n".join(lines) + "\n")


def read_manifest(directory: Path) -> dict[str, str] | None:
    """``MANIFEST.sha256`` as name -> sha256, or None if the directory has none."""
    path = directory / MANIFEST_FILE
    if not path.is_file():
        return None
    entries = {}
    data = read_bounded(path, MAX_MANIFEST_BYTES, ChecksumError, "restore it")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ChecksumError(f"{path} is not UTF-8 text: restore it") from error
    for number, line in enumerate(text.splitlines(), start=1):
        match = _SHA256_LINE.match(line)
        if match is None or match.group(2) in (".", ".."):
            raise ChecksumError(f"{path}, line {number}: expected '<64 hex digits>  <file name>'; got {line[:100]!r}")
        if match.group(2) in entries:
            raise ChecksumError(
                f"{path}, line {number}: {match.group(2)} is listed a second time (each file once): restore it"
            )
        entries[match.group(2)] = match.group(1)
    return entries


class _VerifiedReader:
    """Reads the files of one policy directory, each checked against the manifest (if any)."""

    def __init__(self, directory: Path, require_manifest: bool) -> None:
        self.directory = directory
        self.manifest = read_manifest(directory)
        if self.manifest is None and require_manifest:
            raise ChecksumError(
                f"{directory} has no {MANIFEST_FILE}: a shipped model must have one; restore the directory "
                f"from the repository"
            )
        if self.manifest is not None and require_manifest:
            listed = set(self.manifest) | {MANIFEST_FILE}
            present = {path.name for path in directory.iterdir()}
            unlisted, missing = sorted(present - listed), sorted(listed - present)
            if unlisted or missing:
                raise ChecksumError(
                    f"{directory} does not match its {MANIFEST_FILE}: "
                    + (f"files not listed: {unlisted}; " if unlisted else "")
                    + (f"listed files missing: {missing}; " if missing else "")
                    + "restore the directory from the repository"
                )

    def read(self, name: str) -> bytes:
        path = self.directory / name
        if not path.is_file():
            raise PolicyFormatError(f"{path} is missing: restore it, or re-create the policy directory")
        # Checked before reading: a file's cost is bounded by its kind, not by what it claims.
        limit = MAX_JSON_BYTES if name.endswith(".json") else MAX_TENSOR_FILE_BYTES
        size = path.stat().st_size
        if size > limit:
            raise PolicyFormatError(
                f"{path} is {size:,} bytes, more than a policy file can be ({limit:,} for a "
                f"{'JSON' if name.endswith('.json') else 'safetensors'} file): restore or re-create it"
            )
        data = read_bounded(path, limit, PolicyFormatError, "restore or re-create it")
        if self.manifest is not None:
            if name not in self.manifest:
                raise ChecksumError(f"{path} is not listed in {self.directory / MANIFEST_FILE}: the manifest is stale")
            actual = sha256_hex(data)
            if actual != self.manifest[name]:
                raise ChecksumError(
                    f"{path}: SHA-256 {actual} does not match {MANIFEST_FILE} ({self.manifest[name]}); the file "
                    f"is corrupted or was changed: restore it (for a shipped model, git checkout the directory)"
                )
        return data


def verify_manifest(directory: str | Path, strict: bool = True) -> None:
    """Check every file listed in ``directory``'s manifest (and, if ``strict``, that the manifest
    lists exactly the directory's files). Raises :class:`ChecksumError` naming the file."""
    directory = Path(directory)
    reader = _VerifiedReader(directory, require_manifest=strict)
    for name in reader.manifest or {}:
        reader.read(name)


# ---------------------------------------------------------------------------------------------
# Saving
# ---------------------------------------------------------------------------------------------


def tensor_bytes(tensors: Mapping[str, torch.Tensor], metadata: Mapping[str, str] | None = None) -> bytes:
    """``tensors`` (and text ``metadata``) as the bytes of a safetensors file."""
    # Cloned so that no two entries share storage, which safetensors refuses.
    return _safetensors().save(
        {key: value.detach().cpu().contiguous().clone() for key, value in tensors.items()},
        metadata=dict(metadata) if metadata else None,
    )


def load_tensors(data: bytes, where: Path) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file's bytes, by name in sorted order; a PolicyFormatError
    naming ``where`` if malformed.

    Sorted because safetensors hands them back in an order that changes from process to process
    (a hash map's), and what is built from them keeps it: a resumed run wrote its optimizer
    state in that order, so the same seed gave different bytes."""
    try:
        tensors = _safetensors().load(data)
    except Exception as error:  # noqa: BLE001 - safetensors raises its own error types for bad headers
        raise PolicyFormatError(
            f"{where} is not a valid safetensors file ({error}): restore or re-create it"
        ) from error
    for name, tensor in tensors.items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise PolicyFormatError(f"{where}: tensor {name!r} has NaN or infinite entries: restore or re-create it")
    return dict(sorted(tensors.items()))


def policy_metadata(
    model: BaseAlgorithm,
    env_id: str | None,
    provenance: Mapping[str, Any] | None,
    normalization: bool,
    training_state: bool,
    spec: PolicySpec | None = None,
    algo: str | None = None,
) -> dict[str, Any]:
    """The ``policy.json`` of ``model`` (see the module docstring): ``spec`` says how its outputs
    become actions (default: a centralised policy whose outputs are its actions); ``algo`` names a
    training algorithm of :data:`POLICY_HOSTS` whose policy ``model`` holds (default: ``model``'s
    own)."""
    spec = spec or PolicySpec()
    if algo is not None and POLICY_HOSTS.get(algo) is not type(model):
        host = type(model).__name__
        raise PolicyFormatError(f"algo {algo!r} is not one of {sorted(POLICY_HOSTS)} with a {host} policy")
    policy_class = model.policy_class
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "algo": algo or _algo_name(model),
        "env_id": env_id,
        "policy": policy_alias(model),
        "policy_kwargs": encode_policy_kwargs(policy_constructor_kwargs(model), policy_class),
        "observation_space": encode_space(model.observation_space, "observation_space"),
        "action_space": encode_space(model.action_space, "action_space"),
        "num_timesteps": int(model.num_timesteps),
        "normalization": normalization,
        "training_state": training_state,
        "residual_on": spec.residual_on,
        "multiagent": None if spec.multiagent is None else json_value(dict(spec.multiagent), "multiagent"),
        "versions": package_versions(POLICY_PACKAGES),
        "provenance": json_value(dict(provenance or {}), "provenance"),
    }


def save_policy(
    directory: str | Path,
    model: BaseAlgorithm,
    normalizer: VecNormalize | NormalizationStatistics | None,
    env_id: str | None,
    provenance: Mapping[str, Any] | None = None,
    training_state: bool = False,
    extra_files: Iterable[str] = (),
    spec: PolicySpec | None = None,
    algo: str | None = None,
) -> Path:
    """Write ``model``'s policy (and ``normalizer``'s statistics) to ``directory`` in the safe
    format; with ``training_state``, also the optimizer states and counters that resuming needs;
    ``spec`` (default: a centralised policy whose outputs are its actions) and ``algo`` as in
    :func:`policy_metadata`.
    Every file is written atomically, the manifest last; it also covers ``extra_files`` (names
    of files already in ``directory``, such as ``config.yml``). Returns the directory."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    statistics = (
        NormalizationStatistics.from_vec_normalize(normalizer) if isinstance(normalizer, VecNormalize) else normalizer
    )
    metadata = policy_metadata(model, env_id, provenance, statistics is not None, training_state, spec, algo)
    written = [METADATA_FILE, WEIGHTS_FILE]
    atomic_write_bytes(directory / WEIGHTS_FILE, tensor_bytes(model.policy.state_dict()))
    if statistics is not None:
        atomic_write_text(directory / NORMALIZATION_FILE, statistics.to_json())
        written.append(NORMALIZATION_FILE)
    else:
        (directory / NORMALIZATION_FILE).unlink(missing_ok=True)
    if training_state:
        tensors, meta = capture_training_state(model)
        atomic_write_bytes(directory / TRAINING_STATE_FILE, tensor_bytes(tensors))
        atomic_write_text(directory / TRAINING_META_FILE, dump_json(meta))
        written += [TRAINING_STATE_FILE, TRAINING_META_FILE]
    else:
        for name in (TRAINING_STATE_FILE, TRAINING_META_FILE):
            (directory / name).unlink(missing_ok=True)
    atomic_write_text(directory / METADATA_FILE, dump_json(metadata))
    write_manifest(directory, written + [name for name in extra_files if (directory / name).is_file()])
    return directory


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass
class LoadedPolicy:
    """A policy rebuilt from a policy directory.

    Attributes:
        policy: the SB3 policy (``predict(obs, deterministic=True)``), on the CPU, in eval mode.
        metadata: the parsed ``policy.json``.
        normalizer: the observation statistics, or None if the policy was trained without.
        directory: where it was loaded from.
    """

    policy: BasePolicy
    metadata: dict[str, Any]
    normalizer: NormalizationStatistics | None
    directory: Path

    @property
    def spec(self) -> PolicySpec:
        """How the policy's outputs become actions (its ``residual_on`` and ``multiagent``)."""
        return PolicySpec.from_metadata(self.metadata)


def is_policy_dir(path: str | Path) -> bool:
    """Whether ``path`` is a directory in the safe policy format (it holds ``policy.json``)."""
    return Path(path).is_dir() and (Path(path) / METADATA_FILE).is_file()


def read_metadata(directory: Path, reader: _VerifiedReader | None = None) -> dict[str, Any]:
    """The parsed and checked ``policy.json`` of ``directory``."""
    reader = reader or _VerifiedReader(directory, require_manifest=False)
    where = directory / METADATA_FILE
    metadata = parse_json(reader.read(METADATA_FILE), where)
    if require_entry(metadata, "format", str, where) != FORMAT:
        raise PolicyFormatError(f"{where} is not a tether-gym policy file (format {metadata['format']!r})")
    if require_entry(metadata, "format_version", int, where) != FORMAT_VERSION:
        raise PolicyFormatError(
            f"{where}: format_version {metadata['format_version']} is not {FORMAT_VERSION}: use the tether-gym "
            f"version that wrote it"
        )
    require_entry(metadata, "algo", str, where)
    require_entry(metadata, "policy", str, where)
    require_entry(metadata, "env_id", (str, type(None)), where)
    require_entry(metadata, "policy_kwargs", dict, where)
    require_entry(metadata, "num_timesteps", int, where)
    require_entry(metadata, "normalization", bool, where)
    require_entry(metadata, "training_state", bool, where)
    # Optional (policies written before residual training have none): the baseline the
    # policy's actions are corrections to.
    from ..controllers.residual import check_residual_on

    try:
        metadata["residual_on"] = check_residual_on(metadata.get("residual_on"), f"{where}: residual_on")
    except ValueError as error:
        raise PolicyFormatError(str(error)) from None
    # Optional (centralised policies have none): the multi-agent options of a shared
    # decentralised policy, which acts on local observations (agents.controllers.decentralised).
    multiagent = metadata.get("multiagent")
    if multiagent is not None and not isinstance(multiagent, dict):
        raise PolicyFormatError(
            f"{where}: multiagent must be a dict of multi-agent options or null; got {multiagent!r}"
        )
    metadata["multiagent"] = multiagent
    return metadata


def load_policy(directory: str | Path, require_manifest: bool = False, device: str = "cpu") -> LoadedPolicy:
    """Rebuild the policy stored in ``directory`` (see the module docstring).

    With ``require_manifest`` (shipped models), the directory must have a ``MANIFEST.sha256``
    that lists exactly its files; otherwise a manifest is verified when present. The network's
    size is computed from ``policy.json`` and checked against :data:`.size.MAX_POLICY_PARAMETERS`
    and the weights file's value count before the policy is built; an unbounded action space is
    refused. Raises :class:`PolicyFormatError` (or :class:`ChecksumError`) naming the file and the
    problem."""
    directory = Path(directory)
    if not is_policy_dir(directory):
        raise PolicyFormatError(f"{directory} is not a policy directory (it has no {METADATA_FILE})")
    reader = _VerifiedReader(directory, require_manifest)
    metadata = read_metadata(directory, reader)
    where = directory / METADATA_FILE
    policy_class = _policy_class(metadata["algo"], metadata["policy"], str(where))
    observation_space = decode_space(metadata.get("observation_space"), f"{where}: observation_space")
    action_space = decode_space(metadata.get("action_space"), f"{where}: action_space")
    kwargs = decode_policy_kwargs(metadata["policy_kwargs"], policy_class, f"{where}: policy_kwargs")
    check_action_bounds(action_space, f"{where}: action_space")
    # What the network costs, and that the weights hold exactly that many values, before anything
    # is built: building allocates and initialises every weight the file asks for.
    size = parameter_count(
        metadata["algo"],
        metadata["policy_kwargs"],
        math.prod(observation_space.shape),
        math.prod(action_space.shape),
        f"{where}: policy_kwargs",
    )
    weights = load_tensors(reader.read(WEIGHTS_FILE), directory / WEIGHTS_FILE)
    stored = sum(tensor.numel() for tensor in weights.values())
    if stored != size:
        raise PolicyFormatError(
            f"{directory / WEIGHTS_FILE} holds {stored:,} values, but the network that {where} describes has "
            f"{size:,} parameters: the two files do not belong together; restore or re-create the policy directory"
        )
    try:
        # Building the policy draws its random initial weights: keep the caller's torch RNG as it was.
        with torch.random.fork_rng(devices=[]):
            policy = policy_class(observation_space, action_space, _constant_schedule, **kwargs)
    except Exception as error:  # noqa: BLE001 - only allow-listed classes run here; any failure is bad kwargs
        raise PolicyFormatError(f"{where}: policy_kwargs do not build a {policy_class.__name__}: {error}") from error
    _load_state_dict(policy, weights, directory / WEIGHTS_FILE)
    policy.to(device)
    policy.set_training_mode(False)
    normalizer = None
    if metadata["normalization"]:
        normalizer = NormalizationStatistics.from_json(reader.read(NORMALIZATION_FILE), directory / NORMALIZATION_FILE)
        if normalizer.obs_mean.shape != observation_space.shape:
            raise PolicyFormatError(
                f"{directory / NORMALIZATION_FILE}: statistics of shape {normalizer.obs_mean.shape} do not fit the "
                f"observation space {observation_space.shape} of {where}"
            )
    return LoadedPolicy(policy=policy, metadata=metadata, normalizer=normalizer, directory=directory)


def _load_state_dict(module: torch.nn.Module, weights: Mapping[str, torch.Tensor], where: Path) -> None:
    """``module.load_state_dict(weights, strict=True)`` after checking names, shapes and dtypes,
    with errors that name the file and the tensors."""
    _check_state_dict(module, weights, where)
    module.load_state_dict(weights, strict=True)


def _check_state_dict(module: torch.nn.Module, weights: Mapping[str, torch.Tensor], where: Path) -> None:
    """Refuse ``weights`` unless they have exactly ``module``'s tensor names, shapes and dtypes."""
    expected = module.state_dict()
    missing, unexpected = sorted(set(expected) - set(weights)), sorted(set(weights) - set(expected))
    if missing or unexpected:
        raise PolicyFormatError(
            f"{where} does not fit the policy that policy.json describes: "
            + (f"missing tensors {missing[:5]}{' ...' if len(missing) > 5 else ''}; " if missing else "")
            + (f"unexpected tensors {unexpected[:5]}{' ...' if len(unexpected) > 5 else ''}" if unexpected else "")
        )
    for key, tensor in expected.items():
        if weights[key].shape != tensor.shape or weights[key].dtype != tensor.dtype:
            raise PolicyFormatError(
                f"{where}: tensor {key!r} has shape {tuple(weights[key].shape)} ({weights[key].dtype}); the policy "
                f"needs {tuple(tensor.shape)} ({tensor.dtype})"
            )


def check_resumable(
    metadata: Mapping[str, Any],
    algo: str,
    label: str,
    env_id: str | None = None,
    spec: PolicySpec | None = None,
    normalize: bool | None = None,
) -> None:
    """Refuse to resume training ``algo`` from the policy directory whose ``policy.json`` is
    ``metadata`` when a recorded setting that changes what its weights mean differs from the run
    being resumed: a :class:`PolicyFormatError` when it holds another algorithm's model, was
    trained on another id (``env_id``, when given), keeps no optimizer state, was trained as
    another kind of policy (``spec``, when given: ``residual_on``, whose outputs are corrections
    to a baseline's actions, and ``multiagent``), or with normalisation on where ``normalize`` is
    off or the other way round (when given). ``label`` names the directory at the start of the
    message (``--resume DIR``, or the file that was read); every message names the entry of
    ``policy.json`` and the hyperparameter to set."""
    if metadata["algo"] != algo:
        raise PolicyFormatError(
            f"{label} is a {metadata['algo']} checkpoint; resume it with --algo {metadata['algo']} (not {algo})"
        )
    if env_id is not None and metadata["env_id"] != env_id:
        raise PolicyFormatError(
            f"{label} was trained on {metadata['env_id']}; resume it with --env {metadata['env_id']} (not {env_id})"
        )
    if not metadata["training_state"]:
        raise PolicyFormatError(
            f"{label} holds a policy for inference only (no optimizer state): resume from a checkpoint that "
            f"{program('train')} wrote (<run>/checkpoints/<algo>_<steps>_steps, <run>/best or the run directory)"
        )
    settings = "resume with the run's hyperparameters (its config.yml: --hyperparams, or --set)"
    if spec is not None:
        recorded = PolicySpec.from_metadata(metadata)
        if recorded.residual_on != spec.residual_on:
            raise PolicyFormatError(
                f"{label}: {METADATA_FILE} records residual_on: {recorded.residual_on}, the run's hyperparameters "
                f"{spec.residual_on}: "
                + (
                    f"the checkpoint's outputs are corrections to {recorded.residual_on}'s actions, not actions"
                    if recorded.residual_on is not None
                    else "the checkpoint's outputs are actions, not corrections to a baseline's"
                )
                + f"; {settings}"
            )
        ours = None if spec.multiagent is None else json_value(dict(spec.multiagent), "multiagent")
        if recorded.multiagent != ours:
            raise PolicyFormatError(
                f"{label}: {METADATA_FILE} records multiagent: {recorded.multiagent}, the run's hyperparameters "
                f"{ours}: a decentralised policy acts on local observations, a centralised one on the whole "
                f"cluster's; {settings}"
            )
    if normalize is not None and metadata["normalization"] != normalize:
        raise PolicyFormatError(
            f"{label}: {METADATA_FILE} records normalization: {str(metadata['normalization']).lower()}, but the run's "
            f"hyperparameters' 'normalize' is {'on' if normalize else 'off'}: the weights expect "
            f"{'normalised' if metadata['normalization'] else 'raw'} observations; {settings}"
        )


def load_training_state(
    model: BaseAlgorithm,
    directory: str | Path,
    normalizer: VecNormalize | None,
    spec: PolicySpec | None = None,
) -> dict[str, Any]:
    """Resume ``model`` (freshly built with the run's hyperparameters) from the policy directory
    ``directory``: its weights, optimizer states, extra variables and counters, and the
    normalisation statistics into ``normalizer``. Returns the checkpoint's metadata.

    Every file is read and checked before anything is written into ``model`` or ``normalizer``:
    the recorded settings (:func:`check_resumable`, with ``spec``, the run's residual and
    multi-agent settings, when given), the policy's class, arguments and spaces, the weights, every
    optimizer tensor against its parameter, and the statistics' shape.

    Raises :class:`PolicyFormatError` naming the file and the entry when the directory has no
    training state, or when it does not fit ``model`` (another algorithm, kind of policy,
    architecture, space or normalisation)."""
    directory = Path(directory)
    if not is_policy_dir(directory):
        raise PolicyFormatError(f"{directory} is not a policy directory (it has no {METADATA_FILE})")
    reader = _VerifiedReader(directory, require_manifest=False)
    metadata = read_metadata(directory, reader)
    where = directory / METADATA_FILE
    algo = _algo_name(model)
    check_resumable(metadata, algo, str(directory), spec=spec, normalize=normalizer is not None)
    ours = encode_policy_kwargs(policy_constructor_kwargs(model), model.policy_class)
    differing = sorted(
        key for key in set(ours) | set(metadata["policy_kwargs"]) if ours.get(key) != metadata["policy_kwargs"].get(key)
    )
    if differing or policy_alias(model) != metadata["policy"]:
        details = "; ".join(
            f"{key}: checkpoint {metadata['policy_kwargs'].get(key)!r}, now {ours.get(key)!r}" for key in differing
        )
        raise PolicyFormatError(
            f"{where}: the checkpoint's policy differs from the one the hyperparameters build ({details or 'policy'}): "
            f"resume with the run's hyperparameters (its config.yml)"
        )
    for key in ("observation_space", "action_space"):
        recorded = decode_space(metadata.get(key), f"{where}: {key}")
        if recorded != getattr(model, key):
            raise PolicyFormatError(
                f"{where}: {key} (shape {list(recorded.shape)}) differs from the env's (shape "
                f"{list(getattr(model, key).shape)}) or its bounds: resume on the id and env settings it was "
                "trained with"
            )
    weights = load_tensors(reader.read(WEIGHTS_FILE), directory / WEIGHTS_FILE)
    _check_state_dict(model.policy, weights, directory / WEIGHTS_FILE)
    meta_where = directory / TRAINING_META_FILE
    meta = parse_json(reader.read(TRAINING_META_FILE), meta_where)
    if require_entry(meta, "format", str, meta_where) != TRAINING_STATE_FORMAT:
        raise PolicyFormatError(f"{meta_where} is not a tether-gym training state")
    if require_entry(meta, "format_version", int, meta_where) != FORMAT_VERSION:
        raise PolicyFormatError(
            f"{meta_where}: format_version {meta['format_version']} is not {FORMAT_VERSION}: use the tether-gym "
            "version that wrote it"
        )
    tensors = load_tensors(reader.read(TRAINING_STATE_FILE), directory / TRAINING_STATE_FILE)
    restore = check_training_state(model, meta, tensors, algo, meta_where, directory / TRAINING_STATE_FILE)
    statistics = None
    if normalizer is not None:
        statistics_where = directory / NORMALIZATION_FILE
        statistics = NormalizationStatistics.from_json(reader.read(NORMALIZATION_FILE), statistics_where)
        # The run's normaliser settings (its hyperparameters' 'normalize' options) were replaced by
        # the checkpoint's without a word: a run asking for norm_reward: false continued with it on.
        theirs, ours_settings = (
            statistics.settings(),
            NormalizationStatistics.settings_of(normalizer),
        )
        differing = [key for key in theirs if theirs[key] != ours_settings[key]]
        if differing:
            raise PolicyFormatError(
                f"{statistics_where} records "
                + ", ".join(f"{key}: {theirs[key]!r} (the run's: {ours_settings[key]!r})" for key in differing)
                + ": the weights were trained on observations normalised with the checkpoint's settings; resume with "
                "the run's hyperparameters (its config.yml: --hyperparams, or --set normalize=...)"
            )
        if statistics.obs_mean.shape != normalizer.obs_rms.mean.shape:
            raise PolicyFormatError(
                f"{statistics_where}: obs_rms.mean has shape {list(statistics.obs_mean.shape)}; the env's "
                f"observations have {list(normalizer.obs_rms.mean.shape)}: restore or re-create the checkpoint"
            )
    model.policy.load_state_dict(weights, strict=True)
    restore()
    if statistics is not None and normalizer is not None:
        statistics.apply_to(normalizer)
    return metadata
