#!/usr/bin/env bash
# Runs the whole test suite (installing first if .venv is missing). CI calls this script.
set -euo pipefail
cd "$(dirname "$0")"
if ! .venv/bin/python -c "import pde2cad, ezdxf, OCP, open3d, pytest" 2>/dev/null || ! command -v potrace >/dev/null; then
  ./setup.sh --install-only
fi
exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
