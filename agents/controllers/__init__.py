"""The controllers room: scripted controllers of the damping task and what they share.

* :mod:`.base`: the :class:`~.base.Controller` base class (observation decoding, the
  ``predict`` interface, saturation counting), :func:`~.base.task_of` (the task behind any
  wrapped env) and the Protocols naming what the evaluation expects of a controller.
* :mod:`.linear_model`: the cluster's elastic modes and its linearised, sampled model.
* :mod:`.centralised`: passive, velocity feedback, LQR and the tension-aware law, which read the
  whole cluster's state.
* :mod:`.decentralised`: the local laws, each thruster acting on what its own satellite
  measures, and the local observer that runs a shared decentralised policy on the single-agent envs.
* :mod:`.mpc`: the privileged model-predictive reference controller ``mpc``.
* :mod:`.residual`: a learned correction on top of a scripted baseline's action.
* :mod:`.registry`: :data:`~.registry.BASELINES`, every scripted baseline by name, and
  :func:`~.registry.make_baseline`.

Nothing here registers itself on import: the registry lists every baseline explicitly.
"""
