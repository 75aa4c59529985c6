"""The damping task on clusters whose tethers have mass (beads): nominal shape, reset noise on the
tethers' low modes, and the per-tether observation block.

A cluster with beads (see :mod:`tether_gym.tethers`) keeps its satellites first; the task puts
thrusters, observations, the bias thrust and the deviation limit on the satellites only.  What
the beads need of the task lives here:

* :func:`nominal_cluster`: the cluster at the static equilibrium of its beads (in a turning frame
  a tether across the frame's load sags; in free space the straight line is already the
  equilibrium, since every segment carries the same pretension).
* :func:`tether_modes_noise`: reset noise drawn on the satellites and on each tether's lowest
  transverse sine modes, never independently per bead (independent noise per bead stretches
  every stiff segment and puts hundreds of joules into the line).
* :func:`tether_features`: each tether's observation block, in the order of
  :data:`~tether_gym.envs.contract.TETHER_FEATURES`.
"""

from __future__ import annotations

import numpy as np

from tether_gym.cluster import Cluster
from tether_gym.envs.arguments import EnvArgumentError
from tether_gym.envs.contract import TETHER_FEATURES, TETHER_MODES
from tether_gym.tethers import static_equilibrium

__all__ = ["nominal_cluster", "tether_features", "tether_modes_noise"]


def nominal_cluster(cluster: Cluster) -> Cluster:
    """``cluster`` itself without beads or in an inertial frame; in a turning frame, the cluster
    with its beads at their static equilibrium (:func:`~tether_gym.tethers.static_equilibrium`),
    its satellites where they were.

    Raises:
        EnvArgumentError: the beads have no equilibrium (a slack tether in a turning frame).
    """
    if not cluster.num_beads or cluster.frame.is_inertial:
        return cluster
    try:
        equilibrium = static_equilibrium(cluster)
    except ValueError as error:
        raise EnvArgumentError(
            f"cluster {cluster.name!r}: its tethers' beads have no static equilibrium in its frame, so the task has "
            f"no nominal shape ({error})"
        ) from None
    return cluster.replace(positions=equilibrium.positions)


def _bead_fractions(cluster: Cluster, tether: int) -> np.ndarray:
    """(N - 1,) positions of tether ``tether``'s beads along it, as fractions j / N."""
    segments = cluster.tethers[tether].segments
    return np.arange(1, segments) / segments


def _across(cluster: Cluster, tether: int, positions: np.ndarray) -> np.ndarray:
    """(3, 3) projector across the chord of tether ``tether`` in ``positions`` (n, 3)."""
    a, b = cluster.tethers[tether].ends
    chord = positions[b] - positions[a]
    direction = chord / np.linalg.norm(chord)
    return np.eye(3) - np.outer(direction, direction)


def _transverse_directions(cluster: Cluster, tether: int, chord: np.ndarray) -> np.ndarray:
    """(B, 2, 3) the unit directions ``lateral`` and ``normal`` across tether ``tether`` whose
    current chords are ``chord`` (B, 3), m (see :data:`~tether_gym.envs.contract.TETHER_DIRECTIONS`):
    ``lateral = r x e / |r x e|``, ``normal = e x lateral``, with ``r`` the z axis, or the x axis
    when the nominal chord is within 45 degrees of z (fixed per tether, so that the directions
    turn smoothly with the line)."""
    a, b = cluster.tethers[tether].ends
    nominal = cluster.positions[b] - cluster.positions[a]
    reference = np.array([1.0, 0.0, 0.0]) if abs(nominal[2]) > np.sqrt(0.5) * np.linalg.norm(nominal) else np.eye(3)[2]
    unit = chord / np.maximum(np.linalg.norm(chord, axis=1, keepdims=True), 1e-300)
    lateral = np.cross(reference, unit)
    # A chord along r (a line bent far from its nominal direction) has no lateral: report 0 there.
    lateral /= np.maximum(np.linalg.norm(lateral, axis=1, keepdims=True), 1e-300)
    return np.stack([lateral, np.cross(unit, lateral)], axis=1)


def tether_modes_noise(
    cluster: Cluster, rng: np.random.Generator, count: int, displacement_std: float, velocity_std: float
) -> tuple[np.ndarray, np.ndarray]:
    """(count, n, 3) random displacements (m) and velocities (m/s) of a cluster with beads.

    Each satellite's components are Gaussian with std ``displacement_std`` and ``velocity_std``.
    Each bead follows its tether's ends linearly, plus the first ``TETHER_MODES`` transverse sine
    modes ``sin(k pi j / N)`` of the tether, whose amplitudes are Gaussian vectors across the
    nominal chord with std ``displacement_std / k`` and ``velocity_std / k`` (lower modes carry
    more, as in a line shaken at its ends).  The draws come from ``rng`` in a fixed order:
    satellite displacements (count, S, 3), satellite velocities, then the modal amplitudes
    (count, T, TETHER_MODES, 3) of displacements and of velocities.
    """
    S, n, T = cluster.num_satellites, cluster.num_nodes, cluster.num_tethers
    satellite_displacement = displacement_std * rng.standard_normal((count, S, 3))
    satellite_velocity = velocity_std * rng.standard_normal((count, S, 3))
    modes = np.arange(1, TETHER_MODES + 1)
    displacement_modes = rng.standard_normal((count, T, TETHER_MODES, 3)) * (displacement_std / modes)[:, None]
    velocity_modes = rng.standard_normal((count, T, TETHER_MODES, 3)) * (velocity_std / modes)[:, None]
    displacement = np.zeros((count, n, 3))
    velocity = np.zeros((count, n, 3))
    displacement[:, :S] = satellite_displacement
    velocity[:, :S] = satellite_velocity
    for t, spec in enumerate(cluster.tethers):
        beads = cluster.tether_beads(t)
        if not beads.size:
            continue
        a, b = spec.ends
        fraction = _bead_fractions(cluster, t)[None, :, None]  # (1, N-1, 1)
        shapes = np.sin(np.pi * modes[:, None] * _bead_fractions(cluster, t)[None, :])  # (K, N-1)
        across = _across(cluster, t, cluster.positions)
        for total, ends, amplitudes in (
            (displacement, satellite_displacement, displacement_modes),
            (velocity, satellite_velocity, velocity_modes),
        ):
            linear = (1.0 - fraction) * ends[:, a, None, :] + fraction * ends[:, b, None, :]
            transverse = np.einsum("km,ckd->cmd", shapes, amplitudes[:, t] @ across)
            total[:, beads] = linear + transverse
    return displacement, velocity


def tether_features(
    cluster: Cluster, positions: np.ndarray, tension: np.ndarray, broken: np.ndarray, length_scale: float
) -> np.ndarray:
    """(B, T, len(TETHER_FEATURES)) each tether's observation entries (see
    :data:`~tether_gym.envs.contract.TETHER_FEATURES`) from (B, n, 3) positions (m), (B, m)
    cable tensions (N) and (B, m) broken flags; lengths in units of ``length_scale`` (m),
    tensions in units of the tether's pretension ``N0`` (N; in N when ``N0 = 0``), signed modal
    amplitudes in the two directions of :data:`~tether_gym.envs.contract.TETHER_DIRECTIONS`."""
    B = positions.shape[0]
    features = np.zeros((B, cluster.num_tethers, len(TETHER_FEATURES)))
    modes = np.arange(1, TETHER_MODES + 1)
    for t, spec in enumerate(cluster.tethers):
        segments = cluster.tether_cables(t)
        chain = cluster.tether_nodes(t)
        steps = positions[:, chain[1:]] - positions[:, chain[:-1]]
        length = np.sqrt((steps * steps).sum(axis=2)).sum(axis=1)
        unit = spec.N0 if spec.N0 > 0.0 else 1.0
        line = np.where(broken[:, segments], 0.0, tension[:, segments])
        features[:, t, 0] = (length - float(spec.L0 or 0.0)) / length_scale
        features[:, t, 1] = line[:, 0] / unit
        features[:, t, 2] = line[:, -1] / unit
        features[:, t, 3] = (line <= 0.0).mean(axis=1)
        beads = cluster.tether_beads(t)
        if beads.size:
            a, b = spec.ends
            start = positions[:, a, None, :]
            chord = positions[:, b, None, :] - start
            offset = positions[:, beads, :] - start
            along = (offset * chord).sum(axis=2) / np.maximum((chord * chord).sum(axis=2), 1e-300)
            across = offset - along[:, :, None] * chord  # (B, N-1, 3)
            shapes = np.sin(np.pi * modes[:, None] * _bead_fractions(cluster, t)[None, :])  # (K, N-1)
            amplitudes = (2.0 / spec.segments) * np.einsum("km,bmd->bkd", shapes, across)  # (B, K, 3) m
            directions = _transverse_directions(cluster, t, chord[:, 0, :])  # (B, 2, 3)
            signed = np.einsum("bkd,bed->bke", amplitudes, directions)  # (B, K, 2): mode-major, as TETHER_FEATURES
            features[:, t, 4:] = signed.reshape(B, -1) / length_scale
    return features
