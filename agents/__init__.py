"""Controllers for the tether-gym damping task: scripted baselines, RL training and comparison.

Installed (the ``train`` extra: ``pip install "tether-gym[train]"``), the package is
``tether_gym_agents`` (``from tether_gym_agents.baselines import make_baseline``) and its commands
are console scripts (``tether-gym-train``, ``tether-gym-compare``, ``tether-gym-benchmark``, ...,
or ``python -m tether_gym_agents.train``). In a checkout it is also importable as ``agents``
(``python -m agents.train``), the name the module references below use; see
:mod:`agents.common.commands`. Its modules import each other relatively.

* :mod:`agents.baselines`: passive, velocity feedback, LQR and a tension-aware energy law, each
  a policy with Stable-Baselines3's ``predict`` interface.
* :mod:`agents.policies`: load a trained SB3 policy (with its ``VecNormalize`` statistics) as a
  policy of the same interface; look up controllers by name.
* :mod:`agents.safe_format`: the policy files (JSON, safetensors, a checksum manifest), which
  load without running code; :mod:`agents.pickled`: SB3's pickle-based files, only on opt-in;
  :mod:`agents.convert`: ``python -m agents.convert``, from the second to the first.
* :mod:`agents.common.files`: the commands' careful output files (checked first, atomic, no symlinks).
* :mod:`agents.train`: ``python -m agents.train``, SB3 training driven by ``agents/hyperparams``.
* :mod:`agents.evaluate`: rollouts on held-out seeds and the comparison metrics.
* :mod:`agents.compare`: ``python -m agents.compare``, the side-by-side table and plots.
* :mod:`agents.mpc`: the privileged model-predictive reference controller ``mpc``.
* :mod:`agents.residual`: policies trained as corrections to a scripted baseline.
* :mod:`agents.benchmark`: ``python -m agents.benchmark``, every id, controller and statistic.
* :mod:`agents.common.commands`: the commands' names and console scripts under either package name.
"""

# tether_gym sets the OpenMP spin policy (tether_gym._kernels) when it is imported. Importing it
# before torch gives torch's own OpenMP threads the same policy, so that they do not starve the
# simulator's threads in a training process.
import tether_gym  # noqa: F401, E402
