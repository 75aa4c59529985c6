#!/usr/bin/env bash
# Build the documentation site into outputs/site/ (ignored by git): install the `docs` extra into
# .venv, then `mkdocs build --strict`, so a broken link or anchor, or a page missing from the
# navigation, fails. The home page is the README, and each environment id's page is generated
# from the code during the build (docs/hooks/env_pages.py), which makes every env once.
# Extra arguments go to `mkdocs build` (e.g. --site-dir DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh "docs"
.venv/bin/python -m mkdocs build --strict --site-dir outputs/site "$@"
