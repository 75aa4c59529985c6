#!/usr/bin/env bash
# The Ray RLlib tests, in their own venv (.venv-rllib): Ray pins gymnasium (1.2.2 for Ray 2.60), older
# than the main venv's, so the env tests run there too, to check the package under that pin.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=.venv-rllib bash scripts/install.sh "rllib,dev"
.venv-rllib/bin/python -c "import gymnasium, ray; print(f'ray {ray.__version__}, gymnasium {gymnasium.__version__}')"
.venv-rllib/bin/python -m pytest -m rllib tests/agents/training/test_rllib.py tests/agents/evaluation/test_ceiling_ray.py "$@"
.venv-rllib/bin/python -m pytest -m "not slow" tests/envs "$@"
