"""Environment ids for ``gymnasium.make``: one per preset, all version 0.

``gym.make("tether_gym:TetherTetrahedron-v0")`` works without importing tether_gym first.

:data:`ENV_IDS` says what each id builds, and :data:`ENV_DOCS` what its documentation page says
beyond the env class's docstring. The site's build (``docs/hooks/env_pages.py``) makes each id's
page from these, the class docstring of :class:`~tether_gym.envs.TetherClusterEnv`, the preset's
docstring and the registered spec, so a page and the code cannot disagree.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym

#: The task settings of the orbital radial chain: its cables carry only about 0.1 N, so it gets
#: cold-gas thrusters of 0.1 N, gentler initial conditions, and 0.5 s control intervals over its
#: ~4 s axial period (200 s episodes).
ORBITAL_TASK: dict[str, Any] = {
    "control_interval": 0.5,
    "max_thrust": 0.1,
    "initial_displacement": 0.02,
    "initial_velocity": 0.02,
}

#: id -> (preset, max_episode_steps, task keyword arguments).  300 steps of 0.1 s = 30 s per episode
#: unless the task says otherwise.
ENV_IDS: dict[str, tuple[str, int, dict[str, Any]]] = {
    "TetherTetrahedron-v0": ("tetrahedron", 300, {}),
    "TetherChain-v0": ("chain", 300, {}),
    "TetherTriangle-v0": ("triangle", 300, {}),
    "TetherOctahedron-v0": ("octahedron", 300, {}),
    "TetherHub-v0": ("hub", 300, {}),
    "TetherRadialChain-v0": ("radial_chain", 400, ORBITAL_TASK),
    "TetherSpinningTriangle-v0": ("spinning_triangle", 300, {}),
    "TetherSpinningHub-v0": ("spinning_hub", 300, {}),
    "TetherBeadedTetrahedron-v0": ("beaded_tetrahedron", 300, {}),
    "TetherBeadedChain-v0": ("beaded_chain", 300, {}),
    "TetherDelayedTetrahedron-v0": ("tetrahedron", 300, {"thrust_delay": 2, "observe_commands": True}),
    "TetherCoarseBeadedTetrahedron-v0": ("beaded_tetrahedron", 300, {"preset_kwargs": {"segments": 4}}),
    "TetherOnOffTetrahedron-v0": ("tetrahedron", 300, {"thrust_mode": "on_off"}),
}

#: The hard track: ids where the best scripted law, its gains re-tuned for the id, costs at least
#: :data:`HARD_TRACK_MIN_EXCESS_COST` more than the reference ceiling on held-out seeds
#: (agents/evaluation/ceiling.py), so that a learned controller has room to win.
#: ``TetherCoarseBeadedTetrahedron-v0`` (tethers with mass) qualifies: its best re-tuned law,
#: ``tension_aware``, costs 25.4 % [22.5, 28.3] more than the ceiling there. Candidates that left
#: less room once each law was designed for its task stay off the track: thrusters on two of the
#: tetrahedron's four satellites left 7.7 %, on one of them 6.5 % (tuning seeds, laws not re-tuned),
#: a chain with thrusters on its ends about 2 %;
#: ``TetherDelayedTetrahedron-v0`` left 13.8 % until the laws predicted the state their command
#: meets over the delay, and 7.7 % after (against a ceiling planned around the predicting law).
#: ``TetherOnOffTetrahedron-v0`` (on/off thrusters, ``thrust_mode="on_off"``) qualifies narrowly:
#: its best re-tuned law, ``tension_aware``, costs 10.8 % [8.8, 12.8] more than the ceiling on the 64
#: held-out seeds. ``agents/hyperparams/ceiling.yml`` and ``laws.yml`` record the measurements. The other ids of
#: :data:`ENV_IDS` are the standard track. Every id here is an id of :data:`ENV_IDS`, in its order.
HARD_TRACK: tuple[str, ...] = ("TetherCoarseBeadedTetrahedron-v0", "TetherOnOffTetrahedron-v0")

#: The least excess cost over the reference ceiling, ``(-R[law]) / (-R[ceiling]) - 1`` averaged
#: over the held-out seeds, of the best scripted law (its gains re-tuned for the id on tuning
#: seeds) for an id to qualify for :data:`HARD_TRACK`: 0.1 is 10 % of the ceiling's cost.
HARD_TRACK_MIN_EXCESS_COST = 0.10


def track_of(env_id: str) -> str:
    """``"hard"`` for an id of :data:`HARD_TRACK`, else ``"standard"``: the track whose tables
    and aggregates an id's results belong to (the two are never aggregated together)."""
    return "hard" if env_id in HARD_TRACK else "standard"


#: The paper's case, and the default task.
DEFAULT_ENV_ID = "TetherTetrahedron-v0"


@dataclasses.dataclass(frozen=True)
class EnvDoc:
    """What one id's documentation page says beyond the env class's docstring.

    Numbers the code knows (the spaces' sizes, the episode length, the control interval, the
    thrust, the cluster's masses and lengths) are not written here: the page renders them from
    the registered spec, a freshly made env and the preset's signature.

    Attributes:
        summary: one line, for tables of ids.
        description: Markdown paragraphs: what the cluster is, what holds it in shape and what
            makes this id's task different from the others.
        version_history: one Markdown line per version of the id, oldest first.
    """

    summary: str
    description: str
    version_history: tuple[str, ...]


#: A change of every id's vector env, recorded in each id's version history (the single env and
#: both modes' trajectories are unchanged, so the ids keep version 0).
_NEXT_STEP_DEFAULT = (
    "v0, vector env: `gym.make_vec` autoresets on the next step by default, as Gymnasium's own vector envs "
    '(whose wrappers assume it); same-step, the default before, is `autoreset_mode="same_step"`.'
)
_FREE_SPACE_V0 = ("v0: initial release, with the single-cluster environments (commit `f1e1c8d`).", _NEXT_STEP_DEFAULT)
_BEADED_V0 = ("v0: initial release, with the tethers with mass (commit `32d2543`).",)
_DELAYED_V0 = (
    "v0: initial release, on the hard track; the id left the track, unchanged, once the scripted laws "
    "predicted the state their command meets over the delay.",
)
_COARSE_BEADED_V0 = ("v0: initial release, on the hard track.",)
_ON_OFF_V0 = ("v0: initial release, on the hard track.",)
_TURNING_FRAME_V0 = ("v0: initial release, with the turning frames (commit `4490cf3`).", _NEXT_STEP_DEFAULT)

#: id -> its documentation beyond the class docstring (see :class:`EnvDoc`); one entry per id of
#: :data:`ENV_IDS`.
ENV_DOCS: dict[str, EnvDoc] = {
    "TetherTetrahedron-v0": EnvDoc(
        summary="The paper's case: four satellites at the corners of a regular tetrahedron. The default id.",
        description=(
            "The example of the source paper: four satellites at the corners of a regular tetrahedron, "
            "joined by its six edges, in free space. Pretension pulls every satellite toward the centroid, "
            "so a constant bias thrust holds the nominal shape, and the agent's thrust is added to it.\n\n"
            "The pretension strain is tiny next to the random initial displacements, so at the start most "
            "cables are slack and the cluster vibrates by cables snapping taut and going slack again. This "
            "is the id of the main job (`bash scripts/main.sh`) and of the shipped default model."
        ),
        version_history=_FREE_SPACE_V0,
    ),
    "TetherChain-v0": EnvDoc(
        summary="Satellites in a straight line, each tethered to the next, in free space.",
        description=(
            "Satellites in a straight line along x, each tethered to its neighbours, in free space and held "
            "by a bias thrust. Only the cables along the line resist stretching; sideways, a satellite is "
            "held only by the pretension of its two cables, so the lateral modes are far softer and slower "
            "than the axial ones. A controller has to damp both."
        ),
        version_history=_FREE_SPACE_V0,
    ),
    "TetherTriangle-v0": EnvDoc(
        summary="Three satellites in an equilateral triangle in the x-y plane, in free space.",
        description=(
            "Three satellites at the corners of an equilateral triangle in the x-y plane, in free space and "
            "held by a bias thrust. In the plane the triangle is a stiff frame; out of the plane the cables "
            "resist motion only through their pretension, so the out-of-plane modes are soft."
        ),
        version_history=_FREE_SPACE_V0,
    ),
    "TetherOctahedron-v0": EnvDoc(
        summary="Six satellites at the vertices of a regular octahedron, twelve cables.",
        description=(
            "Six satellites at the vertices of a regular octahedron, joined along its twelve edges, in free "
            "space and held by a bias thrust. Each satellite meets four cables, so a controller coordinates "
            "more thrusters over more coupled modes than on the tetrahedron."
        ),
        version_history=_FREE_SPACE_V0,
    ),
    "TetherHub-v0": EnvDoc(
        summary="A heavy hub satellite with lighter satellites on spokes around it, closed by a rim.",
        description=(
            "A heavy hub satellite with lighter satellites around it in the x-y plane, each tethered to the "
            "hub and, through the rim, to its neighbours; free space, held by a bias thrust. The unequal "
            "masses exercise the mass-aware critical-step estimate, and the light outer satellites move "
            "much more than the hub for the same cable force."
        ),
        version_history=_FREE_SPACE_V0,
    ),
    "TetherRadialChain-v0": EnvDoc(
        summary="Satellites on the local vertical of a circular orbit (Hill frame), held taut by the gravity gradient.",
        description=(
            "Satellites in a line along the local vertical of a circular low Earth orbit, simulated in the "
            "Hill (Clohessy-Wiltshire) frame. The gravity gradient, not thrust, holds the cables taut: their "
            "pretension is the tidal pull of everything outboard, so the bias thrust is zero to round-off. "
            "That pull is weak, so the cables are barely taut and slack easily.\n\n"
            "The id registers its own task settings (`tether_gym.registration.ORBITAL_TASK`, listed below): "
            "weaker thrusters, gentler initial conditions and a longer control interval, matched to the "
            "weak cables and the slow axial period. The cables damp only the axial modes (Kelvin-Voigt "
            "damping; diagonal damping would destabilise motion in the Hill frame); the lateral modes, "
            "far slower, are left to the controller."
        ),
        version_history=_TURNING_FRAME_V0,
    ),
    "TetherSpinningTriangle-v0": EnvDoc(
        summary="An equilateral triangle spinning about its normal, seen in the rotating frame; spin holds it taut.",
        description=(
            "Three satellites in an equilateral triangle spinning about its normal (z), simulated in the "
            "frame that spins with it. The centripetal load of the spin, not thrust, holds the cables taut: "
            "their pretension is that load, so the bias thrust is zero to round-off, and the cables stay "
            "taut more of the time than in free space.\n\n"
            "The cables carry Kelvin-Voigt damping instead of the paper's diagonal damping, which would act "
            "on velocities relative to the spinning frame. Coriolis and centrifugal forces couple the "
            "in-plane modes."
        ),
        version_history=_TURNING_FRAME_V0,
    ),
    "TetherSpinningHub-v0": EnvDoc(
        summary="A hub with satellites on a wheel around it, spinning about z, seen in the rotating frame.",
        description=(
            "A hub satellite with lighter satellites on a wheel around it, spinning about z and simulated in "
            "the frame that spins with it. Spokes and rim share the centripetal load of the spin "
            "(`rim_share`), which sets their pretensions, so the bias thrust is zero to round-off. The "
            "cables carry Kelvin-Voigt damping, as in the other turning-frame ids."
        ),
        version_history=_TURNING_FRAME_V0,
    ),
    "TetherBeadedTetrahedron-v0": EnvDoc(
        summary=(
            "The paper's tetrahedron with tethers of mass, as lines of beads whose waves the thrusters reach "
            "only through the lines."
        ),
        description=(
            "The tetrahedron of the paper's case with each of its six tethers given mass (a fifth of a "
            "satellite's) and split into segments, with beads carrying the mass. The thrusters and the "
            "satellite observations are on the four satellites only; each tether adds a block of its own to "
            "the observation (elongation, end tensions, slack, and its lowest transverse modal amplitudes). "
            "The initial state is drawn on the satellites and the lines' low modes, and the reward's "
            "vibration energy includes the beads.\n\n"
            "The lines are slow and heavy: under their small pretension a line's lowest transverse mode "
            "(below) has a period of about twice an episode. A slack line does not spring back as a "
            "massless cable does; it drags, and snaps taut later. The scripted laws are designed on the "
            "cluster without its beads (see the baselines' page)."
        ),
        version_history=_BEADED_V0,
    ),
    "TetherBeadedChain-v0": EnvDoc(
        summary="The chain with tethers of mass, as lines of beads that carry a third of its mass.",
        description=(
            "The chain of satellites in a line with each tether given mass and split into segments, with "
            "beads carrying the mass: a third of the chain's mass is in its lines. Thrusters and satellite "
            "observations are on the satellites only, with a block per tether in the observation; the "
            "initial state is drawn on the satellites and the lines' low modes.\n\n"
            "Sideways, a massless chain is held only by its pretension; here the lines' own slow transverse "
            "waves couple into that soft lateral motion, and the satellites reach them only through the "
            "lines' ends."
        ),
        version_history=_BEADED_V0,
    ),
    "TetherDelayedTetrahedron-v0": EnvDoc(
        summary="The paper's tetrahedron with each command acting two control steps late.",
        description=(
            "The tetrahedron of the paper's case, with every thrust command acting two control intervals "
            "after it is given, as thrusters behind a slow valve, a command bus and a flight computer "
            "do. The observation ends with the two commands still in flight, oldest first, as the flight "
            "computer knows what it sent: with them the state is observed, and a controller can predict "
            "the state its command will meet. An episode's first intervals have no command yet to act, "
            "and fly with the bias thrust alone.\n\n"
            "Feedback on the present velocity then pushes against where the satellite was, not where it "
            "is: a law has to act on a prediction of the state the command will meet. The scripted laws "
            "do (a Smith predictor: the observed state advanced over the delay with the commands in "
            "flight, on the law's model of the cluster). With it the best of them comes closer to the "
            "reference ceiling than the hard track's margin, so the id is on the standard track; without "
            "it the same laws cost far more (agents/hyperparams/laws.yml has the numbers)."
        ),
        version_history=_DELAYED_V0,
    ),
    "TetherCoarseBeadedTetrahedron-v0": EnvDoc(
        summary=(
            "The tetrahedron with tethers of mass, each line as four segments: waves that no scripted law "
            "damps well, at a fraction of the finer lines' compute. On the hard track."
        ),
        description=(
            "The beaded tetrahedron of the tethers with mass (the same lines, masses, "
            "pretension, wave speed and initial conditions), with each line split into four segments "
            "instead of eight: three beads a line, whose lowest transverse mode is within three percent of "
            "the continuous line's. That mode, about twice an episode long, carries the lines' energy; the "
            "finer lines add faster modes and a smaller critical time step, and cost several times the "
            "compute per simulated second. This id is the one a long-horizon planner (the reference "
            "ceiling) and the trainers can afford.\n\n"
            "The satellites' thrusters reach the lines' waves only through the lines' ends, and a slack "
            "line drags instead of springing back. Every scripted law, its gains re-tuned for this id, "
            "leaves far more cost to the reference ceiling than on the massless ids: the id is on the hard "
            "track (the numbers are below, in agents/hyperparams/laws.yml and in ceiling.yml)."
        ),
        version_history=_COARSE_BEADED_V0,
    ),
    "TetherOnOffTetrahedron-v0": EnvDoc(
        summary=(
            "The paper's tetrahedron with on/off thrusters: each axis fires at full thrust or not at all "
            "over a control interval. On the hard track."
        ),
        description=(
            "The tetrahedron of the paper's case, with thrusters as cold-gas and small chemical thrusters "
            "are: a valve per axis that is open or shut. Over each control interval every axis of every "
            "thruster fires at its full thrust along the sign of its command, or not at all; a command "
            "component of at least half of full scale fires it (the glance table above). The smallest "
            "impulse an axis can give, its minimum impulse bit, is the full thrust times the control "
            "interval, so the last of the motion cannot be braked smoothly: a thruster overshoots it or "
            "leaves it.\n\n"
            "A law that commands a thrust in proportion to a velocity thrusts in bursts instead; its gains "
            "have to be re-tuned for the quantised thrust, and even then it fires where a planner that "
            "knows the pulses holds off. Every scripted law, its gains re-tuned for this id, leaves at "
            "least the hard track's margin of cost to the reference ceiling (the numbers are in "
            "agents/hyperparams/laws.yml and ceiling.yml)."
        ),
        version_history=_ON_OFF_V0,
    ),
}


def register_envs() -> None:
    """Register every id (idempotent)."""
    for env_id, (preset, steps, task) in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="tether_gym.envs.cluster_env:TetherClusterEnv",
            vector_entry_point="tether_gym.envs.vector_env:TetherClusterVectorEnv",
            max_episode_steps=steps,
            kwargs={"preset": preset, **task},
        )
