"""Controllers for the tether-gym damping task: scripted baselines, RL training and comparison.

* :mod:`agents.baselines`: passive, velocity feedback, LQR and a tension-aware energy law, each
  a policy with Stable-Baselines3's ``predict`` interface.
* :mod:`agents.policies`: load a trained SB3 model (with its ``VecNormalize`` statistics) as a
  policy of the same interface; look up controllers by name.
* :mod:`agents.train`: ``python -m agents.train``, SB3 training driven by ``agents/hyperparams``.
* :mod:`agents.evaluate`: rollouts on held-out seeds and the comparison metrics.
* :mod:`agents.compare`: ``python -m agents.compare``, the side-by-side table and plots.
"""
