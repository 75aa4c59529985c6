"""The training room: the trainers' configuration (:mod:`.config`), the hyperparameter files and
their schema (:mod:`.hyperparams`), run directories (:mod:`.runs`), the SB3 callbacks
(:mod:`.callbacks`), model selection on fixed evaluation seeds (:mod:`.selection`), and one module
per training loop (:mod:`.sb3`, with its residual-action env :mod:`.residual_env`; :mod:`.rllib`;
:mod:`.ars`), with shipping a run's policy (:mod:`.shipping`). Nothing heavy is imported here."""
