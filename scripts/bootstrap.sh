#!/usr/bin/env bash
# One-shot, idempotent set-up on a fresh Debian machine (Python 3.11, root, no display):
#   - Debian packages: espeak-ng (offline speech synthesis), Mesa EGL/GL for offscreen MuJoCo rendering;
#   - a virtual environment in .venv with the pinned dependencies (constraints.txt) and this package (editable).
# Re-running is cheap: it only reinstalls when pyproject.toml, constraints.txt or this script changed.
set -euo pipefail
cd "$(dirname "$0")/.."

# chromium + chromium-driver: the live page's browser test (tests/live/test_live_browser.py) drives Debian's
# headless Chromium through selenium; no browser build is downloaded
APT_PACKAGES=(espeak-ng libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgles2 chromium chromium-driver)
PYTHON=${PYTHON:-python3.11}
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3

missing=()
for package in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed" || missing+=("$package")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "bootstrap: installing Debian packages: ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

stamp_source=$(cat pyproject.toml constraints.txt setup.py scripts/bootstrap.sh | sha256sum | cut -d' ' -f1)
if [ ! -x .venv/bin/python ] || [ "$(cat .venv/.bootstrap-stamp 2>/dev/null)" != "$stamp_source" ]; then
  echo "bootstrap: creating .venv and installing pinned dependencies (first run takes a few minutes)" >&2
  [ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
  .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
  .venv/bin/python -m pip install -q --disable-pip-version-check -c constraints.txt -e '.[dev]'
  echo "$stamp_source" > .venv/.bootstrap-stamp
fi
