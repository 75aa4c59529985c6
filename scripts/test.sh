#!/usr/bin/env bash
# Install everything the test-suite needs into .venv, then run it.
set -euo pipefail
cd "$(dirname "$0")/.."
# docs: the API reference and browser-check tests (the browser itself: scripts/install_chromium.sh).
bash scripts/install.sh "dev,plots,train,multiagent,docs"
.venv/bin/python -m pytest "$@"
