#!/usr/bin/env bash
# Train PPO on every id with several seeds, then ship the best run per id (chosen on the evaluation
# seeds, never the benchmark's held-out ones) and record every run in agents/models/training_runs.md.
# Usage: bash scripts/train_all.sh [SEEDS...]   (default seeds 1 2 3; two runs at a time, one thread
# each, so that the two cores are both used). Run directories go to runs/all/<id>/ppo_seed<seed>/,
# each with its TensorBoard logs, config.yml (with the exact command) and best/evaluations.json.
# On this 2-core machine the 24 runs of the default took about an hour.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots,train"
seeds=("${@:-1 2 3}")
ids=$(.venv/bin/python -c "import tether_gym; print(' '.join(tether_gym.ENV_IDS))")
jobs=()
for seed in ${seeds[@]}; do
    for id in $ids; do jobs+=("$id $seed"); done
done
mkdir -p runs/all
printf '%s\n' "${jobs[@]}" | OMP_NUM_THREADS=1 xargs -P 2 -L 1 sh -c \
    '.venv/bin/python -m agents.train --algo ppo --env "$0" --seed "$1" --out runs/all --eval-freq 100000 \
     --eval-episodes 64 --checkpoint-freq 1000000 --no-progress > "runs/all/$0_seed$1.log" 2>&1 \
     && echo "trained $0 seed $1"'
# The models shipped before stay in the running: the best on the evaluation seeds is shipped.
.venv/bin/python -m agents.ship runs/all/*/ppo_seed* agents/models/*/ppo --out agents/models --force
