#!/usr/bin/env bash
# The main job: install into .venv, then compare the scripted baselines and the shipped trained
# model on the default id (held-out seeds): table printed, Markdown/CSV and plots in outputs/compare/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots,train"
# --force: outputs/compare/ is this script's own output directory, rebuilt from the committed code
# and models on every run, so a rerun is meant to replace it (agents.compare alone refuses to
# overwrite an earlier comparison). It applies only to that directory: if the caller picks
# another place with --out, the command's careful default (no overwriting) stays in force there.
force=(--force)
for argument in "$@"; do
    case "$argument" in --out | --out=*) force=() ;; esac
done
.venv/bin/python -m agents.compare --out outputs/compare ${force[@]+"${force[@]}"} "$@"
