#!/usr/bin/env bash
# Open the built documentation site in a real browser (headless Chromium) and fail on console
# errors, failed requests (404s) and images that do not load; screenshots of a few pages go to
# outputs/site_screenshots/. CI runs it after scripts/docs.sh. It installs Debian's chromium if
# missing (as root, with apt-get) and reuses outputs/site if it is built (else builds it).
# Arguments go to scripts/docs_browser_check.py (--site DIR, --out DIR, --chromium PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_chromium.sh
if [ ! -f outputs/site/index.html ]; then
    bash scripts/docs.sh
else
    # The docs extra holds playwright, the browser's driver.
    bash scripts/install.sh "docs"
fi
.venv/bin/python scripts/docs_browser_check.py --chromium "$(command -v chromium)" "$@"
