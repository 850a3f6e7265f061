# Sourced by scripts/demo.sh and scripts/test.sh: idempotent environment set-up.
# Re-installs only when pyproject.toml (or the Blender requirements) changed since last time.
set -euo pipefail
# pip warns on every install run as root (containers, CI): the environments here are venvs.
export PIP_ROOT_USER_ACTION=ignore

find_python() {
  for c in "${PYTHON:-}" python3.11 python3; do
    [ -n "$c" ] || continue
    if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
      echo "$c"; return 0
    fi
  done
  echo "taichi-frac needs Python 3.11 (bpy 5.0 and taichi 1.7 wheels): set PYTHON=/path/to/python3.11" >&2
  return 1
}

stamp_of() { cat "$@" | sha256sum | cut -c1-16; }

setup_main() {
  local py; py=$(find_python)
  local stamp; stamp=$(stamp_of pyproject.toml)
  if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv"; "$py" -m venv .venv
  fi
  if [ "$(cat .venv/.taichi-frac-stamp 2>/dev/null)" != "$stamp" ]; then
    echo "[setup] installing taichi-frac and its dependencies into .venv"
    .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
    .venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test]"
    echo "$stamp" > .venv/.taichi-frac-stamp
  fi
}

setup_blender() {
  # Blender as a Python module lives in its own environment: it bundles its own USD (pxr)
  # and must not meet usd-core. The add-on itself needs nothing but bpy.
  local py; py=$(find_python)
  local stamp; stamp=$(stamp_of scripts/blender-requirements.txt)
  if [ ! -x .venv-blender/bin/python ]; then
    echo "[setup] creating .venv-blender (Blender 5.0 as a Python module, ~370 MB)"; "$py" -m venv .venv-blender
  fi
  if [ "$(cat .venv-blender/.taichi-frac-stamp 2>/dev/null)" != "$stamp" ]; then
    .venv-blender/bin/python -m pip install -q --disable-pip-version-check -r scripts/blender-requirements.txt
    echo "$stamp" > .venv-blender/.taichi-frac-stamp
  fi
}
