#!/usr/bin/env bash
# The main job: install into .venv, then compare the scripted baselines and the shipped trained
# model on the default id (held-out seeds): table printed, Markdown/CSV and plots in outputs/compare/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots,train"
.venv/bin/python -m agents.compare --out outputs/compare "$@"
