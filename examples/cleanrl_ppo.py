"""PPO from scratch on tether-gym's native vector env, in one file, in CleanRL's style.

Bring your own algorithm: this script is the whole training loop of PPO (Schulman et al. 2017)
for continuous actions, written after CleanRL's ``ppo_continuous_action.py``, on
``gym.make_vec(id, num_envs=N)``: the project's own vector env, which steps all N sub-envs in one
compiled batch. At the end it scores the trained policy on the benchmark's held-out episodes
with ``tether_gym_agents.evaluation.scoring.score_policy`` (mean return, the paired difference against the
id's best scripted baseline, and the normalised score: 0 = passive, 100 = mpc), so the result
can be placed in the tables of docs/benchmark.md. Change what you like and compare.

Run from the repository root (needs the ``train`` extra, for torch and the scoring)::

    .venv/bin/python examples/cleanrl_ppo.py                             # 500 000 steps
    .venv/bin/python examples/cleanrl_ppo.py --total-timesteps 20000 --eval-episodes 8
    .venv/bin/python examples/cleanrl_ppo.py --env-id TetherChain-v0 --num-envs 32
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

# Before torch: tether_gym sets the OpenMP spin policy, which torch's threads then share, so
# that the two do not starve each other's threads on a busy machine (agents/__init__.py).
import tether_gym  # noqa: F401

# isort: split
import torch
from tether_gym_agents.evaluation.scoring import score_policy
from torch import nn
from torch.distributions.normal import Normal


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="TetherTetrahedron-v0", help="a tether-gym id")
    parser.add_argument("--total-timesteps", type=int, default=500_000, help="env steps to train for, in all")
    parser.add_argument("--num-envs", type=int, default=16, help="sub-envs of the vector env")
    parser.add_argument("--num-steps", type=int, default=128, help="steps per sub-env per rollout")
    parser.add_argument("--learning-rate", type=float, default=1e-3, help="Adam's, annealed linearly to 0")
    parser.add_argument("--gamma", type=float, default=0.99, help="discount: a horizon of ~100 steps = 10 s")
    parser.add_argument("--gae-lambda", type=float, default=0.95)
    parser.add_argument("--num-minibatches", type=int, default=8)
    parser.add_argument("--update-epochs", type=int, default=10)
    parser.add_argument("--clip-coef", type=float, default=0.2)
    parser.add_argument("--ent-coef", type=float, default=0.0)
    parser.add_argument("--vf-coef", type=float, default=0.5)
    parser.add_argument("--max-grad-norm", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=1, help="seeds torch, numpy and the training envs")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (small nets: 1 is fastest)")
    parser.add_argument("--eval-episodes", type=int, default=64, help="held-out episodes to score on (2..64)")
    args = parser.parse_args()
    args.batch_size = args.num_envs * args.num_steps
    args.minibatch_size = args.batch_size // args.num_minibatches
    args.num_iterations = max(1, args.total_timesteps // args.batch_size)
    return args


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias_const: float = 0.0) -> nn.Linear:
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """CleanRL's actor-critic: two 64-unit tanh MLPs, a state-independent log std."""

    def __init__(self, obs_dim: int, act_dim: int) -> None:
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )
        self.actor_mean = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, act_dim), std=0.01),
        )
        # Thrust noise std e^-1 = 0.37 of full thrust at the start, as agents/hyperparams/ppo.yml:
        # CleanRL's std 1 saturates the thrusters half of the time.
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), -1.0))

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x)

    def get_action_and_value(
        self, x: torch.Tensor, action: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        action_mean = self.actor_mean(x)
        probs = Normal(action_mean, self.actor_logstd.expand_as(action_mean).exp())
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action).sum(1), probs.entropy().sum(1), self.critic(x)


def main() -> None:
    args = parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)

    # The native vector env. Its default autoreset is Gymnasium's next-step mode: the step that
    # ends an episode returns that episode's *final* observation, and the next step of that
    # sub-env ignores its action and resets it (reward 0, the new first observation). We keep
    # next-step (rather than autoreset_mode="same_step" and infos["final_obs"]) because the
    # final observation then arrives as an ordinary next observation, which bootstraps a
    # truncated episode for free, and because Gymnasium's vector wrappers below expect it.
    # What next-step asks of the loop: the reset step is not a transition (masked out below).
    envs = gym.make_vec(f"tether_gym:{args.env_id}", num_envs=args.num_envs)
    envs = gym.wrappers.vector.RecordEpisodeStatistics(envs)  # raw episode returns, before scaling
    envs = normalized = gym.wrappers.vector.NormalizeObservation(envs)
    envs = gym.wrappers.vector.NormalizeReward(envs, gamma=args.gamma)
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]

    agent = Agent(obs_dim, act_dim)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    shape = (args.num_steps, args.num_envs)
    obs = torch.zeros(shape + (obs_dim,))
    actions = torch.zeros(shape + (act_dim,))
    logprobs, rewards, values = torch.zeros(shape), torch.zeros(shape), torch.zeros(shape)
    terminations, dones, valid = torch.zeros(shape), torch.zeros(shape), torch.zeros(shape)

    # Training seeds 1.. stay clear of the held-out seeds (10 000 and up) the score uses.
    next_obs = torch.as_tensor(envs.reset(seed=args.seed)[0], dtype=torch.float32)
    # Sub-envs whose episode ended in the last step: their next step is a reset, not a transition.
    autoreset = np.zeros(args.num_envs, dtype=bool)
    recent_returns: list[float] = []
    global_step, start = 0, time.perf_counter()
    for iteration in range(1, args.num_iterations + 1):
        optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / args.num_iterations) * args.learning_rate

        for step in range(args.num_steps):
            global_step += args.num_envs
            obs[step] = next_obs
            valid[step] = torch.as_tensor(~autoreset, dtype=torch.float32)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs)
            values[step] = value.flatten()
            actions[step], logprobs[step] = action, logprob
            # The log-probability is of the unclipped sample; the env gets it within [-1, 1].
            next_np, reward, terminated, truncated, infos = envs.step(np.clip(action.numpy(), -1.0, 1.0))
            autoreset = terminated | truncated
            rewards[step] = torch.as_tensor(reward, dtype=torch.float32)
            terminations[step] = torch.as_tensor(terminated, dtype=torch.float32)
            dones[step] = torch.as_tensor(autoreset, dtype=torch.float32)
            next_obs = torch.as_tensor(next_np, dtype=torch.float32)
            if "episode" in infos:
                recent_returns = (recent_returns + infos["episode"]["r"][infos["_episode"]].tolist())[-100:]

        # Generalised advantage estimation, backwards in time. values[t + 1] is the value of the
        # observation step t reached: on a step that ended an episode, the final observation.
        # A failure (terminated) has no future; a time limit (truncated) bootstraps from it.
        with torch.no_grad():
            next_value = agent.get_value(next_obs).flatten()
        advantages = torch.zeros(shape)
        last_gae = torch.zeros(args.num_envs)
        for t in reversed(range(args.num_steps)):
            following = next_value if t == args.num_steps - 1 else values[t + 1]
            delta = rewards[t] + args.gamma * following * (1.0 - terminations[t]) - values[t]
            # The sum runs on only within an episode, and a reset step adds nothing.
            last_gae = (delta + args.gamma * args.gae_lambda * (1.0 - dones[t]) * last_gae) * valid[t]
            advantages[t] = last_gae
        returns = advantages + values

        # Only the real transitions enter the loss: the reset steps are left out of the batch.
        keep = torch.nonzero(valid.reshape(-1)).flatten().numpy()
        b_obs, b_actions = obs.reshape(-1, obs_dim)[keep], actions.reshape(-1, act_dim)[keep]
        b_logprobs, b_advantages = logprobs.reshape(-1)[keep], advantages.reshape(-1)[keep]
        b_returns, b_values = returns.reshape(-1)[keep], values.reshape(-1)[keep]
        minibatch = max(1, keep.size // args.num_minibatches)
        for _ in range(args.update_epochs):
            order = rng.permutation(keep.size)
            for begin in range(0, keep.size, minibatch):
                mb = order[begin : begin + minibatch]
                _, newlogprob, entropy, newvalue = agent.get_action_and_value(b_obs[mb], b_actions[mb])
                ratio = (newlogprob - b_logprobs[mb]).exp()
                mb_adv = b_advantages[mb]
                mb_adv = (mb_adv - mb_adv.mean()) / (mb_adv.std() + 1e-8)
                pg_loss = torch.max(
                    -mb_adv * ratio, -mb_adv * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
                ).mean()
                # CleanRL's clipped value loss.
                newvalue = newvalue.flatten()
                v_clipped = b_values[mb] + torch.clamp(newvalue - b_values[mb], -args.clip_coef, args.clip_coef)
                v_loss = 0.5 * torch.max((newvalue - b_returns[mb]) ** 2, (v_clipped - b_returns[mb]) ** 2).mean()
                loss = pg_loss - args.ent_coef * entropy.mean() + args.vf_coef * v_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()

        mean_return = f"{np.mean(recent_returns):8.1f}" if recent_returns else "     n/a"
        print(
            f"iteration {iteration}/{args.num_iterations}  step {global_step}  "
            f"episode return (last {len(recent_returns)}) {mean_return}  "
            f"{global_step / (time.perf_counter() - start):.0f} steps/s",
            flush=True,
        )
    envs.close()
    print(f"trained {global_step} steps in {time.perf_counter() - start:.1f} s")

    # The trained policy as a function of raw observations: the observation statistics of the
    # training run, frozen, then the actor's mean action (deterministic), within [-1, 1].
    mean, std = normalized.obs_rms.mean.copy(), np.sqrt(normalized.obs_rms.var + 1e-8)

    def policy(observation: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = torch.as_tensor((observation - mean) / std, dtype=torch.float32)
            return agent.actor_mean(x).clamp(-1.0, 1.0).numpy()

    score = score_policy(policy, args.env_id, episodes=args.eval_episodes, name="cleanrl_ppo")
    print(score.summary())


if __name__ == "__main__":
    main()
