#!/usr/bin/env bash
# The installed package, checked as a user gets it, by the README's own lines: in a fresh copy of
# the checkout (the files git knows) and with a new, empty HOME, it runs the README's "Install as a
# package" block as written (a venv in ~, the CPU build of torch, the wheel built with
# `python -m build` and installed with the train extra, tether-gym-compile, the comparison), then
# every Python snippet of the README with that venv's interpreter from a directory outside the
# checkout. Then, from there too: every id through gym.make, the shipped models and settings read
# from site-packages, every console script's --help, a short training run and the comparison with
# its model through the console scripts. Anything missing stops it with a non-zero exit and the
# step it failed in.
# Usage: bash scripts/wheel_check.sh  (PYTHON: an interpreter for the helper scripts, default .venv/bin/python)
set -euo pipefail
cd "$(dirname "$0")/.."
checkout=$PWD
helper=${PYTHON:-$checkout/.venv/bin/python}
# Nothing of the checkout may reach the installed package's interpreter.
unset PYTHONPATH PYTHONHOME VIRTUAL_ENV
work=$(mktemp -d "${TMPDIR:-/tmp}/tether-gym-wheel-check.XXXXXX")
trap 'rm -rf "$work"' EXIT
started=$SECONDS
current="starting"
steps=0
step() {
    current=$*
    steps=$((steps + 1))
    echo "[wheel check, $((SECONDS - started)) s] $current"
}
trap 'echo "wheel check FAILED while $current (logs above)" >&2' ERR
# Run a quiet command, showing its output only when it fails.
logged() {
    local log="$work/log.txt"
    if ! "$@" >"$log" 2>&1; then
        grep -v "^WARNING: Location 'file:" "$log" | tail -40 >&2
        return 1
    fi
}

step "reading the README's install lines and Python snippets"
mkdir "$work/source" "$work/run" "$work/home" "$work/snippets"
"$helper" - README.md "$work" <<'EOF_PY'
import re, sys
from pathlib import Path
text = Path(sys.argv[1]).read_text(encoding="utf-8")
work = Path(sys.argv[2])
section = text.split("## Install as a package", 1)[1].split("\n## ", 1)[0]
install = re.findall(r"^```bash\n(.*?)^```", section, re.MULTILINE | re.DOTALL)
assert len(install) == 1, f"expected one bash block under 'Install as a package', found {len(install)}"
(work / "install.sh").write_text(install[0], encoding="utf-8")
# The README installs the same CPU build of torch as scripts/install.sh, so that the two cannot drift.
pins = set(re.findall(r"torch==[0-9][0-9.]*[0-9]", Path("scripts/install.sh").read_text(encoding="utf-8")))
assert len(pins) == 1 and pins <= set(re.findall(r"torch==[0-9][0-9.]*[0-9]", install[0])), (
    f"the README's install lines must pin scripts/install.sh's torch {sorted(pins)}")
snippets = re.findall(r"^```python\n(.*?)^```", text, re.MULTILINE | re.DOTALL)
assert snippets, "the README has no Python snippet"
for index, snippet in enumerate(snippets, start=1):
    (work / "snippets" / f"snippet_{index}.py").write_text(snippet, encoding="utf-8")
print(f"  {len(install[0].splitlines())} install lines, {len(snippets)} Python snippets")
EOF_PY

step "running the README's install lines as written, in a fresh copy of the checkout with an empty HOME"
# From a copy of the files git knows (ignored ones left out), so that nothing is written into the checkout.
git ls-files -z --cached --others --exclude-standard \
    | tar --null --files-from=- --ignore-failed-read -cf - 2>/dev/null | tar -xf - -C "$work/source"
# The new HOME keeps the machine's own pip configuration (its package indexes) and, where Python
# comes from pyenv, pyenv's root, which both default to places under the real HOME.
if [ -d "$HOME/.config/pip" ]; then
    mkdir -p "$work/home/.config" && cp -r "$HOME/.config/pip" "$work/home/.config/"
fi
if command -v pyenv >/dev/null 2>&1; then
    export PYENV_ROOT=${PYENV_ROOT:-$(pyenv root)}
fi
(cd "$work/source" && logged env HOME="$work/home" bash -euo pipefail "$work/install.sh")
venv=$(echo "$work"/home/*/bin)
[ -x "$venv/python" ] || { echo "wheel check: the README's install lines made no venv under ~" >&2; false; }
wheel=$(echo "$work"/source/dist/*.whl)
"$helper" - "$wheel" <<'EOF_PY'
import collections, sys, zipfile
names = zipfile.ZipFile(sys.argv[1]).namelist()
folders = collections.Counter(name.rsplit("/", 1)[0] if "/models/" not in name else "*/models/<id>/<model>" for name in names)
print(f"  {sys.argv[1].rsplit('/', 1)[1]}: {len(names)} files;",
      ", ".join(f"{folder} {count}" for folder, count in sorted(folders.items())))
EOF_PY
grep -qF "| passive |" "$work/source/compare/comparison.md" || { echo "wheel check: the README's comparison wrote no table" >&2; false; }

cd "$work/run"
step "running the README's Python snippets with the installed package, outside the checkout"
for snippet in "$work"/snippets/snippet_*.py; do
    begun=$SECONDS
    logged env HOME="$work/home" "$venv/python" -I "$snippet"
    echo "  $(basename "$snippet"): $((SECONDS - begun)) s"
done

step "using the installed packages: every id, the shipped models and settings, the console scripts"
# -I: isolated mode, neither the environment nor the current directory adds anything to sys.path.
"$venv/python" -I - "$checkout" <<'EOF'
import importlib.metadata, importlib.util, pkgutil, subprocess, sys, sysconfig
from pathlib import Path

import gymnasium as gym
import numpy as np

import tether_gym
import tether_gym_agents
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS
from tether_gym_agents import policies
from tether_gym_agents.common import commands, data
from tether_gym_agents.controllers import mpc

checkout = Path(sys.argv[1]).resolve()
site = Path(sysconfig.get_paths()["purelib"]).resolve()
for package in (tether_gym, tether_gym_agents):
    where = Path(package.__file__).resolve()
    assert where.is_relative_to(site) and not where.is_relative_to(checkout), f"{package.__name__} from {where}"
assert importlib.util.find_spec("agents") is None, "the wheel installed a top-level 'agents'"
for package in ("tether_gym", "tether_gym_agents"):
    assert (site / package / "py.typed").is_file(), f"{package} has no py.typed"
# Every module of every room is in the wheel and imports from it (a room missing from
# pyproject.toml's package list would be left out).
rooms = [info.name for info in pkgutil.walk_packages(tether_gym_agents.__path__, "tether_gym_agents.")]
for name in rooms:
    assert Path(importlib.import_module(name).__file__).resolve().is_relative_to(site), name
sources = sorted(path for path in (checkout / "agents").rglob("*.py") if path.name != "__init__.py" or path.parent.name != "agents")
assert len(rooms) == len(sources), (len(rooms), len(sources))
print(f"  {len(rooms)} modules of tether_gym_agents imported from the wheel")

for env_id in ENV_IDS:
    env = gym.make(env_id)
    observation, _ = env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(5):
        observation, reward, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(observation) and np.isfinite(reward), env_id
    env.close()
vector_env = gym.make_vec(DEFAULT_ENV_ID, num_envs=4)
vector_env.reset(seed=0)
_, rewards, *_ = vector_env.step(vector_env.action_space.sample())
assert rewards.shape == (4,) and np.isfinite(rewards).all()
print(f"  gym.make: {len(ENV_IDS)} ids stepped; gym.make_vec: {DEFAULT_ENV_ID} x 4 stepped")

# The data the agents read at run time, from site-packages: hyperparameters, MPC settings, and
# every shipped model (its checksum manifest verified as it loads).
hyperparams = sorted(path.name for path in data.HYPERPARAMS_DIR.glob("*.yml"))
assert "ppo.yml" in hyperparams and "mpc.yml" in hyperparams, hyperparams
mpc.load_mpc_settings(DEFAULT_ENV_ID)
shipped = {env_id: policies.shipped_models(env_id) for env_id in ENV_IDS}
assert shipped[DEFAULT_ENV_ID], f"no shipped model for {DEFAULT_ENV_ID} in {policies.MODELS_DIR}"
for env_id, models in shipped.items():
    for name, directory in models.items():
        policies.TrainedPolicy(directory)
print(f"  hyperparameters {hyperparams}; {sum(map(len, shipped.values()))} shipped models loaded and verified")

scripts = sorted(
    entry.name
    for entry in importlib.metadata.distribution("tether-gym").entry_points
    if entry.group == "console_scripts"
)
assert set(commands.SCRIPTS.values()) <= set(scripts), scripts
for script in scripts:
    result = subprocess.run([Path(sys.executable).parent / script, "--help"], capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout.startswith(f"usage: {script} "), (script, result.stderr[-2000:])
module_help = subprocess.run([sys.executable, "-m", "tether_gym_agents.train", "--help"], capture_output=True, text=True)
assert module_help.stdout.startswith("usage: python -m tether_gym_agents.train "), module_help.stderr[-2000:]
print(f"  --help: {', '.join(scripts)} and python -m tether_gym_agents.train")
EOF

env_id=$("$venv/python" -I -c "from tether_gym.registration import DEFAULT_ENV_ID; print(DEFAULT_ENV_ID)")
step "a short training run: tether-gym-train on $env_id with the shipped hyperparameters"
# One PPO update of one rollout (8 envs x the YAML's n_steps 256 = its batch size), one evaluation.
"$venv/tether-gym-train" --timesteps 2048 --n-envs 8 --eval-freq 2048 --eval-episodes 2 --no-progress --out runs
run_dir=runs/$env_id/ppo_seed0
for file in policy.json policy.safetensors normalization.json MANIFEST.sha256 config.yml best/policy.json; do
    [ -s "$run_dir/$file" ] || { echo "wheel check: the training run wrote no $run_dir/$file" >&2; false; }
done
grep -q "^command: tether-gym-train " "$run_dir/config.yml"

step "the comparison with the shipped model: tether-gym-compare on $env_id"
"$venv/tether-gym-compare" --controllers passive ppo "$run_dir" --episodes 2 --out compare
for row in "| passive |" "| ppo |" "| $run_dir |"; do
    grep -qF "$row" compare/comparison.md || { echo "wheel check: no row '$row' in comparison.md" >&2; false; }
done
ls compare/*.png >/dev/null

echo "wheel check passed in $((SECONDS - started)) s"
cd "$checkout"
# Removing the venv (about 43 000 files, 1.7 GB) took 17 s to over 2 min here, by the load: timed apart.
rm -rf "$work"
echo "[wheel check, $((SECONDS - started)) s] removed the venv and the work folder"
# The plain closing line CI reads, as a test runner's: each step above is one check, and all passed.
echo "wheel_check: $steps passed, 0 failed"
