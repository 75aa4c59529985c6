"""The named contracts between the layers: the kernels' tables, the task's scalar columns, end
reasons, reward weights and observation layout, and the public accessors that replace reaching
into private fields."""

from __future__ import annotations

import copy
import inspect
import pickle

import gymnasium as gym
import numpy as np
import pytest

import tether_gym as tg
from tether_gym import _kernels
from tether_gym.envs import _task_kernels
from tether_gym.envs.contract import (
    END_REASONS,
    OBSERVATION_BLOCKS,
    REWARD_TERMS,
    SCALARS,
    EndReason,
    ObservationLayout,
    RewardWeights,
    Scalar,
)
from tether_gym.envs.task import task_from_arguments

ENV_ID = "TetherTetrahedron-v0"


def compiled_kernels() -> list[tuple[str, object]]:
    """Every numba dispatcher of the two kernel modules."""
    found = []
    for module in (_kernels, _task_kernels):
        for name, value in vars(module).items():
            if hasattr(value, "py_func") and getattr(value.py_func, "__module__", None) == module.__name__:
                found.append((f"{module.__name__}.{name}", value))
    return found


def test_every_kernel_takes_at_most_ten_arguments() -> None:
    kernels = compiled_kernels()
    assert {"advance_serial", "advance_parallel", "evaluate_serial", "command_forces"} <= {
        name.rsplit(".", 1)[1] for name, _ in kernels
    }
    for name, kernel in kernels:
        count = len(inspect.signature(kernel.py_func).parameters)  # type: ignore[attr-defined]
        assert count <= 10, f"{name} takes {count} arguments"


@pytest.mark.parametrize(
    ("columns", "width"),
    [
        (
            {
                "MASS": 1,
                "DAMPING": 1,
                "REFERENCE": 3,
                "POSITION": 3,
                "HALF_STEP_VELOCITY": 3,
                "VELOCITY": 3,
                "INTERNAL_FORCE": 3,
                "PREVIOUS_FORCE": 3,
                "APPLIED_FORCE": 3,
            },
            "NODE_COLUMNS",
        ),
        (
            {
                name: 1
                for name in (
                    "STIFFNESS",
                    "REST_LENGTH",
                    "PRETENSION",
                    "INV_SPLIT_MASS_SUM",
                    "BREAKING_LOAD",
                    "AXIAL_DAMPING",
                    "TENSION",
                    "INTACT",
                    "PEAK_TENSION",
                )
            },
            "CABLE_COLUMNS",
        ),
        (
            {
                "FRAME_RATE": 1,
                "FRAME_TIDAL": 3,
                **{n: 1 for n in ("TIME", "LAST_STEP", "OMEGA2", "WORK", "DISSIPATED", "INITIAL_ENERGY")},
                "STEP_MIN": 1,
                "STEP_MAX": 1,
                "ENERGY_SCALE": 1,
            },
            "CLUSTER_COLUMNS",
        ),
        ({"STATUS": 1, "SUBSTEPS": 1}, "COUNTER_COLUMNS"),
    ],
)
def test_the_simulator_tables_columns_tile_each_table(columns: dict[str, int], width: str) -> None:
    """Each named column (or 3-column vector) owns its cells, and together they fill the table."""
    cells = sorted(
        c for name, size in columns.items() for c in range(getattr(_kernels, name), getattr(_kernels, name) + size)
    )
    assert cells == list(range(getattr(_kernels, width)))


def test_scalar_columns_are_the_info_keys_and_the_reward_is_the_sum_of_its_terms() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=3)
    task = env.unwrapped.task
    _, reward, _, _, info = env.step(env.action_space.sample())
    assert SCALARS == tuple(column.key for column in Scalar)
    for column in Scalar:
        value = task.scalars[0, column]
        if column.key in info:
            assert info[column.key] == value, column
    assert reward == task.scalars[0, Scalar.REWARD]
    assert reward == pytest.approx(sum(info[term.key] for term in REWARD_TERMS), rel=1e-12)
    assert info["slack_count"] == round(task.scalars[0, Scalar.SLACK_FRACTION] * task.cluster.num_cables)


def test_end_reasons_are_named_once() -> None:
    assert END_REASONS == ("running", "formation_lost", "cable_broken", "numerics_diverged")
    assert [reason.label for reason in EndReason] == list(END_REASONS)
    assert tg.envs.END_REASONS is END_REASONS
    env = gym.make(ENV_ID, max_deviation=1e-6)
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(12))
    task = env.unwrapped.task
    assert terminated and task.end_reason[0] == EndReason.FORMATION_LOST and info["end_reason"] == "formation_lost"
    assert task.terminated().tolist() == [True]


def test_reward_weights_are_named_and_are_what_the_kernel_applies() -> None:
    task = task_from_arguments(2, "tetrahedron", vibration_weight=2.0, propellant_weight=0.5, slack_weight=0.25)
    weights = task.reward_weights
    assert isinstance(weights, RewardWeights)
    assert weights.vibration == 2.0 / task.energy_scale
    assert weights.propellant == 0.5 / task.full_impulse
    assert (weights.slack, weights.failure) == (0.25, task.config.failure_penalty)
    task.reset([np.random.default_rng(k) for k in range(2)], np.arange(2))
    task.step(np.zeros((2, task.action_size)))
    vibration = task.scalars[:, Scalar.VIBRATION_ENERGY]
    np.testing.assert_array_equal(task.scalars[:, Scalar.REWARD_VIBRATION], -weights.vibration * vibration)
    task.weights[0] *= 2.0  # the writable vector the kernel reads
    task.evaluate()
    assert task.reward_weights.vibration == 2.0 * weights.vibration
    np.testing.assert_array_equal(task.scalars[:, Scalar.REWARD_VIBRATION], -2.0 * weights.vibration * vibration)


@pytest.mark.parametrize(
    ("satellites", "cables", "tensions"), [(4, 6, False), (4, 6, True), (2, 3, True), (1, 12, False)]
)
def test_the_observation_layout_tiles_the_vector_in_block_order(satellites: int, cables: int, tensions: bool) -> None:
    layout = ObservationLayout(satellites, cables, tensions)
    slices = [getattr(layout, block.name) for block in OBSERVATION_BLOCKS]
    assert slices[0].start == 0 and slices[-1].stop == layout.size
    assert all(a.stop == b.start for a, b in zip(slices, slices[1:], strict=False))
    widths = [s.stop - s.start for s in slices]
    assert widths == [3 * satellites, 3 * satellites, cables, cables if tensions else 0]
    assert layout.size == 6 * satellites + cables + (cables if tensions else 0)


def test_the_env_docstring_shows_the_layout_of_the_contract() -> None:
    table = ObservationLayout.symbolic_table()
    assert table.splitlines()[2:] == [
        "| 0 .. 3s-1 | " + OBSERVATION_BLOCKS[0].meaning + " | D |",
        "| 3s .. 6s-1 | " + OBSERVATION_BLOCKS[1].meaning + " | V |",
        "| 6s .. 6s+c-1 | " + OBSERVATION_BLOCKS[2].meaning + " | D |",
        "| 6s+c .. 6s+2c-1 | " + OBSERVATION_BLOCKS[3].meaning + " | 1 |",
    ]
    doc = tg.envs.TetherClusterEnv.__doc__ or ""
    assert "\n    ".join(table.splitlines()) in doc and "OBSERVATION_TABLE" not in doc


@pytest.mark.parametrize("observed", [None, (3, 1)])
def test_every_part_of_the_observation_is_what_its_slice_names(observed: tuple[int, ...] | None) -> None:
    """Each slice of the layout against the same quantity computed with numpy from the state."""
    task = task_from_arguments(3, "tetrahedron", observe_tensions=True, observed_satellites=observed)
    task.reset([np.random.default_rng(k) for k in range(3)], np.arange(3))
    task.step(np.random.default_rng(9).uniform(-1, 1, (3, task.action_size)))
    layout, sim = task.observation_layout, task.sim
    obs = task.observation
    assert obs.shape == (3, layout.size) and layout.size == task.observation_size
    masses = sim.masses[:, :, None]
    com = (masses * sim.positions).sum(axis=1, keepdims=True) / masses.sum(axis=1, keepdims=True)
    v_com = (masses * sim.velocities).sum(axis=1, keepdims=True) / masses.sum(axis=1, keepdims=True)
    nominal = task.cluster.positions
    nominal_com = (task.cluster.masses[:, None] * nominal).sum(axis=0) / task.cluster.masses.sum()
    chosen = task.observed
    displacement = ((sim.positions - com) - (nominal - nominal_com))[:, chosen] / task.length_scale
    velocity = (sim.velocities - v_com)[:, chosen] / task.speed_scale
    np.testing.assert_allclose(layout.satellite_values(obs, "displacement"), displacement, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(layout.satellite_values(obs, "velocity"), velocity, rtol=1e-9, atol=1e-9)
    i, j = task.cluster.cables.T
    lengths = np.linalg.norm(sim.positions[:, j] - sim.positions[:, i], axis=-1)
    np.testing.assert_allclose(obs[:, layout.elongation], (lengths - sim.L0) / task.length_scale, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(obs[:, layout.tension_ratio], sim.tension / sim.breaking_load, rtol=1e-12)


def test_public_accessors_give_what_callers_once_read_from_private_fields() -> None:
    task = task_from_arguments(2, "spinning_triangle", thrust_noise=0.1)
    rngs = [np.random.default_rng(k) for k in range(2)]
    task.reset(rngs, np.arange(2))
    task.step(np.ones((2, task.action_size)), rngs=rngs)
    sim = task.sim
    report = sim.energy()
    np.testing.assert_array_equal(sim.work, report.work)
    np.testing.assert_array_equal(sim.dissipated, report.dissipated)
    np.testing.assert_array_equal(sim.initial_energy, report.initial)
    for name in ("work", "dissipated", "initial_energy", "positions", "velocities"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(sim, name)[0] = 0.0
    assert task.perturbed and not task_from_arguments(1, "tetrahedron").perturbed
    last = sim.last_advance
    assert last.substeps.min() > 0 and np.isfinite(last.step_min).all()
    np.testing.assert_array_equal(sim.cluster_indices([True, False]), [0])


def test_copies_and_pickles_keep_their_views_on_their_own_tables() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=1)
    for clone in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        original, copied = env.unwrapped.task, clone.unwrapped.task
        copied.sim.positions_[0] += 1.0
        assert not np.array_equal(original.sim.positions, copied.sim.positions)
        np.testing.assert_array_equal(
            copied.sim.positions, copied.sim.node_table[:, :, _kernels.POSITION : _kernels.POSITION + 3]
        )


# ------------------------------------------------------------------ the split by concern
FLAT_ARGUMENTS = {
    "control_interval": 0.2,
    "thrusters": (0, 2),
    "max_thrust": 0.5,
    "thrust_limit": "magnitude",
    "thrust_mode": "on_off",
    "initial_displacement": 0.02,
    "initial_velocity": 0.05,
    "vibration_weight": 2.0,
    "propellant_weight": 0.3,
    "slack_weight": 0.1,
    "failure_penalty": 50.0,
    "max_deviation": 1.0,
    "observe_tensions": True,
    "observe_commands": True,
    "observation_noise": 0.01,
    "observed_satellites": (1, 3),
    "randomize": {"masses": 0.1},
    "safety_factor": 0.2,
    "allow_unstable_safety_factor": False,
    "impulse_magnitude": 0.5,
    "impulse_rate": 0.2,
    "periodic_amplitude": 0.1,
    "periodic_period": 5.0,
    "thrust_noise": 0.05,
    "thrust_delay": 1,
    "thruster_failure_probability": 0.5,
    "thruster_failure_window": (1.0, 2.0),
    "cable_failure": "continue",
    "difficulty": 0.5,
}


def test_task_config_groups_hold_every_setting_of_their_concern() -> None:
    from tether_gym.envs.config import TASK_CONFIG_GROUPS, TaskConfig

    config = TaskConfig(**FLAT_ARGUMENTS)
    grouped = {name for group in TASK_CONFIG_GROUPS.values() for name in group.__dataclass_fields__}
    top_level = {"control_interval", "thrusters", "max_thrust", "thrust_limit", "thrust_mode", "max_deviation"}
    top_level |= {"observe_tensions"}
    top_level |= {"observation_noise", "observed_satellites", "safety_factor", "allow_unstable_safety_factor"}
    top_level |= {"difficulty", "observe_commands"}
    assert grouped | top_level == set(FLAT_ARGUMENTS) == set(TaskConfig.__dataclass_fields__)
    assert not grouped & top_level
    for attribute, group_type in TASK_CONFIG_GROUPS.items():
        group = getattr(config, attribute)
        assert isinstance(group, group_type)
        for name in group.__dataclass_fields__:
            assert getattr(group, name) == getattr(config, name) == FLAT_ARGUMENTS[name], name
    rebuilt = TaskConfig.from_groups(
        reward=config.reward,
        initial_state=config.initial_state,
        disturbances=config.disturbances,
        faults=config.faults,
        **{name: FLAT_ARGUMENTS[name] for name in top_level},
    )
    assert rebuilt == config


def test_groups_check_their_values_as_the_flat_arguments_do() -> None:
    from tether_gym.envs.config import RewardConfig, TaskConfig
    from tether_gym.envs.disturbances import DisturbanceConfig

    for build in (lambda: TaskConfig(slack_weight=-1.0), lambda: RewardConfig(slack_weight=-1.0)):
        with pytest.raises(tg.envs.EnvArgumentError, match=r"slack_weight must be a finite number in \[0, 1e\+06\]"):
            build()
    with pytest.raises(tg.envs.EnvArgumentError, match="periodic_period"):
        TaskConfig.from_groups(disturbances=DisturbanceConfig(periodic_amplitude=1.0, periodic_period=0.1))
    with pytest.raises(tg.envs.EnvArgumentError, match="slack_weight is given twice"):
        TaskConfig.from_groups(reward=RewardConfig(), slack_weight=1.0)


def test_make_takes_exactly_the_flat_arguments() -> None:
    env = gym.make(ENV_ID, **FLAT_ARGUMENTS)
    config = env.unwrapped.task.config
    assert all(getattr(config, name) == value for name, value in FLAT_ARGUMENTS.items())
    with pytest.raises(
        TypeError, match=r"unknown argument\(s\) \['reward'\]; task arguments are \[.*'vibration_weight'"
    ):
        gym.make(ENV_ID, reward={"vibration_weight": 1.0})


def test_disturbances_and_faults_live_in_their_own_module() -> None:
    from tether_gym.envs.disturbances import Disturbances

    task = task_from_arguments(2, "tetrahedron", thrust_delay=1, thruster_failure_probability=1.0)
    assert isinstance(task.disturbances, Disturbances)
    for name in Disturbances.STATE:
        assert getattr(task, name) is getattr(task.disturbances, name)
    assert task.perturbed is task.disturbances.draws is True


def test_the_finite_difference_reference_lives_in_analysis() -> None:
    from tether_gym.analysis import element_omega2_finite_difference

    batch = tg.BatchSimulator(tg.make_cluster("hub"), 2)
    batch.advance(0.05, np.random.default_rng(0).normal(0, 0.5, (2, batch.num_nodes, 3)))
    np.testing.assert_array_equal(element_omega2_finite_difference(batch), batch.element_omega2_finite_difference())
    with pytest.raises(ValueError, match="relative_perturbation must lie in"):
        element_omega2_finite_difference(batch, 0.5)
