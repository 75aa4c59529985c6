#!/usr/bin/env bash
# The main job: install into .venv, then reproduce the paper's tetrahedron experiment and the
# critical-step study, and the environment demo, writing figures to outputs/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots"
.venv/bin/python examples/paper_tetrahedron.py --out outputs
.venv/bin/python examples/critical_step.py --out outputs
.venv/bin/python examples/env_demo.py --out outputs
