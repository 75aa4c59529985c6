#!/usr/bin/env bash
# Install everything the test-suite needs into .venv, then run it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "dev,plots,train,multiagent"
.venv/bin/python -m pytest "$@"
