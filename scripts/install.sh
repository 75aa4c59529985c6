#!/usr/bin/env bash
# Create .venv (or the venv named by $VENV) if missing and install tether-gym with the extras named in
# $1 (default: dev,plots).
# The CPU build of torch goes in first, so that no extra later pulls a multi-GB CUDA build.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-dev,plots}"
venv="${VENV:-.venv}"
python3 -m venv "$venv"
"$venv"/bin/python -m pip install --quiet --upgrade pip
"$venv"/bin/python -m pip install --quiet "torch==2.13.0"
"$venv"/bin/python -m pip install --quiet -e ".[${extras}]"
