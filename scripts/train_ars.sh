#!/usr/bin/env bash
# Train the ARS linear residual (agents/ars.py) on every id with several seeds, then ship the best
# run per id as agents/models/<id>/ars (chosen on the evaluation seeds, never the benchmark's
# held-out ones; the model shipped before stays in the running) and record every run in
# agents/models/training_runs.md.
# Usage: bash scripts/train_ars.sh [SEEDS...]   (default seeds 1 2 3; two runs at a time, one
# thread each). Run directories go to runs/ars/<id>/ars_seed<seed>/, each with its TensorBoard
# and CSV logs, config.yml (with the exact command) and best/evaluations.json.
set -euo pipefail
shopt -s nullglob
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots,train"
seeds=("${@:-1 2 3}")
ids=$(.venv/bin/python -c "import tether_gym; print(' '.join(tether_gym.ENV_IDS))")
jobs=()
for id in $ids; do
    for seed in ${seeds[@]}; do jobs+=("$id $seed"); done
done
mkdir -p runs/ars
printf '%s\n' "${jobs[@]}" | NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 xargs -P 2 -L 1 sh -c \
    '.venv/bin/python -m agents.ars --env "$0" --seed "$1" --out runs/ars --no-progress --force \
     > "runs/ars/$0_seed$1.log" 2>&1 && echo "trained $0 seed $1"'
.venv/bin/python -m agents.ship runs/ars/*/ars_seed* agents/models/*/ars --out agents/models --force
