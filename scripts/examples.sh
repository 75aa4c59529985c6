#!/usr/bin/env bash
# The physics examples: the paper's tetrahedron experiment, the critical-step study and the env
# demo, writing figures to outputs/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "plots"
.venv/bin/python examples/paper_tetrahedron.py --out outputs
.venv/bin/python examples/critical_step.py --out outputs
.venv/bin/python examples/env_demo.py --out outputs
