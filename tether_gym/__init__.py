"""tether-gym: explicit dynamics of tethered-satellite clusters as reinforcement-learning environments.

The physics follows the lumped-mass, tension-only cable model integrated by explicit central
differences with an element-by-element critical-step estimate.  Main entry points:

* :class:`Cluster`, :func:`make_cluster`, :func:`load_cluster`, :func:`save_cluster`: describe a
  cluster, or take a named preset.
* :class:`Simulator` (one cluster) and :class:`BatchSimulator` (B clusters, one core).
* :class:`Tether`, :func:`build_cluster`: tethers with mass, split into beads and segments
  (:mod:`tether_gym.tethers`).
* :class:`Frame`: inertial, orbiting (Hill / Clohessy-Wiltshire) or spinning frames.
* Gymnasium ids ``TetherTetrahedron-v0`` (default), ``TetherChain-v0``, ``TetherTriangle-v0``,
  ``TetherOctahedron-v0``, ``TetherHub-v0``, and in turning frames ``TetherRadialChain-v0``
  (orbit), ``TetherSpinningTriangle-v0``, ``TetherSpinningHub-v0``:
  :class:`tether_gym.envs.TetherClusterEnv`.
* :mod:`tether_gym.analysis`: tangent stiffness and normal modes for verification and control
  design.
"""

from tether_gym.cluster import Cluster, ClusterError, load_cluster, save_cluster
from tether_gym.frames import LEO_ORBIT_RATE, Frame
from tether_gym.presets import PRESETS, make_cluster, preset_names
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS, HARD_TRACK, register_envs
from tether_gym.simulator import (
    DEFAULT_SAFETY_FACTOR,
    AdvanceStats,
    BatchSimulator,
    EnergyReport,
    SimulationDiverged,
    Simulator,
    SimulatorState,
)
from tether_gym.tethers import Tether, TetherError, build_cluster

__version__ = "0.1.0"

register_envs()

__all__ = [
    "DEFAULT_ENV_ID",
    "DEFAULT_SAFETY_FACTOR",
    "ENV_IDS",
    "HARD_TRACK",
    "PRESETS",
    "AdvanceStats",
    "BatchSimulator",
    "Cluster",
    "ClusterError",
    "EnergyReport",
    "Frame",
    "LEO_ORBIT_RATE",
    "SimulationDiverged",
    "Simulator",
    "SimulatorState",
    "Tether",
    "TetherError",
    "build_cluster",
    "load_cluster",
    "make_cluster",
    "preset_names",
    "save_cluster",
]
