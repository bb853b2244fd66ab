#!/usr/bin/env bash
# Sets up what the project needs on a fresh Debian/Ubuntu machine, then does nothing on later runs:
#  - system packages: Mesa's EGL and llvmpipe (headless OpenGL 4.3), GLX and Xvfb (the viewer's
#    window tests), Qt's X11 libraries (napari's, for the plugin's tests), installed through
#    apt-get when run as root, else named in a message;
#  - a virtual environment .venv with the project and its test dependencies.
# Usage: bash scripts/setup.sh      (from anywhere; paths are relative to the checkout)
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 libgl1 libopengl0 libosmesa6 xvfb xauth
          # Qt's xcb platform, for the napari plugin's tests (napari under Xvfb)
          libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-randr0
          libxcb-render-util0 libxcb-shape0 libxcb-xkb1 libxkbcommon-x11-0
          libdbus-1-3 libfontconfig1)
missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
fi
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing ${missing[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup: missing system packages: ${missing[*]}" >&2
    echo "setup: install them with: sudo apt-get install ${missing[*]}" >&2
    exit 1
  fi
fi

PY=${PYTHON:-python3}
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "setup: Python 3.11 or newer is needed (found: $("$PY" --version 2>&1)); set PYTHON=..." >&2
  exit 1
fi
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv" >&2
  "$PY" -m venv .venv
fi
stamp=.venv/.installed-$(sha1sum pyproject.toml | cut -c1-12)
if [ ! -f "$stamp" ]; then
  echo "setup: installing the project into .venv" >&2
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  # setuptools' editable build says, in a box of asterisks, that a folder named like the package
  # in the working directory could shadow it on import: information only (the package is app/, so
  # none is), which pip 25 and later forward as a BuildBackendWarning. That one warning, matched
  # by its first words in the build's own process, stays quiet; every other warning and error
  # shows as before.
  PYTHONWARNINGS="ignore:Editable installation" .venv/bin/python -m pip install -q -e '.[test]'
  rm -f .venv/.installed-*
  touch "$stamp"
fi
