"""The layout of a policy directory: its files' names, the format's name and version, and the
errors a malformed directory raises.

These sit below every other module of the format (:mod:`.codecs`, :mod:`.normalization`,
:mod:`.sb3_state`, :mod:`.format`), which all name the files and raise the errors; the format
itself is described in :mod:`.format`.
"""

from __future__ import annotations

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MANIFEST_FILE",
    "METADATA_FILE",
    "NORMALIZATION_FILE",
    "POLICY_FILES",
    "TRAINING_META_FILE",
    "TRAINING_STATE_FILE",
    "WEIGHTS_FILE",
    "ChecksumError",
    "PolicyFormatError",
]

#: The ``format`` entry of ``policy.json``.
FORMAT = "tether-gym-policy"
#: The ``format_version`` of every JSON file of a policy directory.
FORMAT_VERSION = 1
#: The metadata: algorithm, env id, policy class and arguments, spaces, versions, provenance.
METADATA_FILE = "policy.json"
#: The policy network's ``state_dict`` (safetensors).
WEIGHTS_FILE = "policy.safetensors"
#: The observation normalisation statistics (JSON), when the policy was trained with them.
NORMALIZATION_FILE = "normalization.json"
#: The optimizer tensors that resuming training needs (safetensors; optional).
TRAINING_STATE_FILE = "training.safetensors"
#: The optimizer settings and counters that resuming training needs (JSON; optional).
TRAINING_META_FILE = "training.json"
#: The SHA-256 of every other file, ``sha256sum`` format.
MANIFEST_FILE = "MANIFEST.sha256"
#: Every file a save may write (the manifest last).
POLICY_FILES = (METADATA_FILE, WEIGHTS_FILE, NORMALIZATION_FILE, TRAINING_STATE_FILE, TRAINING_META_FILE, MANIFEST_FILE)


class PolicyFormatError(ValueError):
    """A policy directory whose files are missing, malformed or inconsistent with each other."""


class ChecksumError(PolicyFormatError):
    """A file of a policy directory whose SHA-256 does not match its ``MANIFEST.sha256``."""
