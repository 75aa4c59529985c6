#!/usr/bin/env bash
# Create .venv (or the venv named by $VENV) if missing and install tether-gym with the extras named in
# $1 (default: dev,plots), saying what each stage does and how long it took.
# The CPU build of torch goes in first, so that no extra later pulls a multi-GB CUDA build.
# A venv that already holds these extras of this pyproject.toml is left as it is (a stamp file
# records what was installed), so the scripts that call this one start at once on a set-up checkout.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-dev,plots}"
venv="${VENV:-.venv}"
torch="torch==2.13.0"
stamp="$venv/.tether-gym-installed"
started=$SECONDS
stage() { echo "[install, $((SECONDS - started)) s] $*"; }

# The stamp: the hash of pyproject.toml, then one extra a line. Up to date when the hash matches
# and every extra asked for is listed.
project_hash=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(head -1 "$stamp")" = "$project_hash" ]; then
    missing=$(tr ',' '\n' <<<"$extras" | grep -vxF -f <(tail -n +2 "$stamp") || true)
    if [ -z "$missing" ]; then
        stage "$venv already has tether-gym[$extras] for this pyproject.toml: nothing to install"
        exit 0
    fi
fi

if [ ! -x "$venv/bin/python" ]; then
    stage "creating the virtual environment $venv"
    python3 -m venv "$venv"
fi
stage "upgrading pip"
"$venv"/bin/python -m pip install --quiet --upgrade pip
stage "installing $torch (the CPU build)"
"$venv"/bin/python -m pip install --progress-bar on "$torch"
stage "installing tether-gym[$extras] (editable) and its dependencies"
"$venv"/bin/python -m pip install --progress-bar on -e ".[${extras}]"

# Every extra installed so far, for this pyproject.toml.
{
    echo "$project_hash"
    { [ -f "$stamp" ] && [ "$(head -1 "$stamp")" = "$project_hash" ] && tail -n +2 "$stamp"; tr ',' '\n' <<<"$extras"; } | sort -u
} >"$stamp.new"
mv "$stamp.new" "$stamp"
stage "done: tether-gym[$extras] in $venv (python -m tether_gym.compile compiles the kernels ahead of first use)"
