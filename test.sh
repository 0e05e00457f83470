#!/usr/bin/env bash
# Runs the whole test suite (installing first if .venv is missing). CI calls this script.
set -euo pipefail
cd "$(dirname "$0")"
# Everything the suite uses: an older .venv or a machine without FreeCAD/Xvfb gets set up again.
if ! .venv/bin/python -c "import pde2cad, ezdxf, OCP, open3d, pytest, mypy, shapely, trimesh, pyinstantmeshes" 2>/dev/null \
   || ! command -v potrace >/dev/null || ! command -v freecadcmd >/dev/null || ! command -v Xvfb >/dev/null; then
  ./setup.sh --install-only
fi
exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
