#!/usr/bin/env bash
# Install Debian's chromium if it is missing: the headless browser of the docs browser check
# (scripts/docs_browser_check.sh) and of its test (tests/docs/test_browser_check.py). As root with
# apt-get; otherwise it says what to run.
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
    exit 0
fi
if [ "$(id -u)" != 0 ]; then
    echo "chromium is not installed; run as root, or: sudo apt-get install -y chromium" >&2
    exit 1
fi
echo "[chromium] installing Debian's chromium (apt-get)"
apt-get update -qq
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
echo "[chromium] $(chromium --version)"
