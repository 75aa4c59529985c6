#!/usr/bin/env bash
# Regenerate every figure of the documentation (docs/img/) and its generated blocks (the
# comparison tables of docs/agents.md, the tutorial's output in docs/tutorial.md) from the code
# they describe: scripts/figures.py declares each output and how it is made, and
# tests/docs/test_figures.py checks that every image the pages show is declared there. About 5
# minutes on 2 cores. Arguments go to scripts/figures.py: --only ENTRY..., --benchmark-dir DIR
# (the --out of a finished `python -m agents.benchmark`, for the benchmark's plots), --env-ids ID...
# (the animations of these ids only).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots,train"
.venv/bin/python scripts/figures.py "$@"
