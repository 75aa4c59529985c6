#!/usr/bin/env bash
# Lint, formatting and types, as CI enforces them: ruff check, ruff format --check, and mypy on
# tether_gym/ (settings in pyproject.toml). Every check runs; the script fails if any of them does.
# By default ruff and mypy (pinned in the dev extra) are installed into .venv first, like
# scripts/test.sh does; PYTHON=/path/to/python uses that interpreter's instead, without installing.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${PYTHON:-}" ]]; then
    bash scripts/install.sh "dev,plots,train"
    PYTHON=.venv/bin/python
fi
failed=()
"$PYTHON" -m ruff check . || failed+=("ruff check")
"$PYTHON" -m ruff format --check . || failed+=("ruff format --check (run: ruff format .)")
"$PYTHON" -m mypy || failed+=("mypy")
if ((${#failed[@]})); then
    printf 'lint: failed: %s\n' "${failed[@]}" >&2
    exit 1
fi
echo "lint: ruff check, ruff format --check and mypy passed"
