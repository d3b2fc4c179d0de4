#!/usr/bin/env bash
# The test command: set-up (idempotent) then the whole suite, headless (EGL) and offline.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
export MUJOCO_GL=egl PYOPENGL_PLATFORM=egl
exec .venv/bin/python -m pytest -q "$@"
