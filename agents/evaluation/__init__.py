"""The evaluation room: controllers run on held-out seeds, and what is measured of them.

* :mod:`.rollout`: :func:`~.rollout.rollout` (E episodes of one controller at once, on seeded
  resets), :class:`~.rollout.EpisodeRecord`, and the comparison's metrics
  (:func:`~.rollout.summarise`, :data:`~.rollout.METRICS`).
* :mod:`.stats`: t intervals, paired differences, the best eligible baseline, normalised scores
  with their paired bootstrap intervals, and rliable's aggregates over ids.
* :mod:`.report`: the Markdown, CSV and JSON tables of the comparison and of the benchmark.
* :mod:`.plots`: their plots (matplotlib, the ``plots`` extra).
* :mod:`.comparison`: ``python -m agents.compare``'s library part, :func:`~.comparison.compare`
  with its :class:`~.comparison.CompareConfig`.
* :mod:`.benchmark`: ``python -m agents.benchmark``'s library part, the run over every id and
  controller, :func:`~.benchmark.benchmark` with its :class:`~.benchmark.BenchmarkConfig`.
* :mod:`.scoring`: :func:`~.scoring.score_policy`, a policy scored against the shipped
  reference scores, and the converter that writes them from a benchmark.

Nothing here is imported by this package's ``__init__``: import the module you need.
"""
