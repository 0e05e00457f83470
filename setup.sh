#!/usr/bin/env bash
# Sets pde2cad up on a fresh Debian machine, then runs the main job on the bundled samples.
#   ./setup.sh                 install everything, then reconstruct examples/clouds and
#                              vectorize examples/images -> out/
#   ./setup.sh --install-only  install only (used by test.sh and CI)
# Installs: Debian packages (potrace for the benchmark peer, libusb-1.0-0 for open3d),
# a virtual environment at .venv with pde2cad and all its optional groups.
set -euo pipefail
cd "$(dirname "$0")"

# freecad-python3: FreeCAD 0.20 (headless) for the surface benchmark's peer and the workbench;
# freecad + xvfb: its GUI (and the GUI test under a virtual display); python3-scipy,
# python3-pil, python3-ezdxf: the pde2cad core and its DXF writer inside FreeCAD's Python;
# fonts-font-awesome: public pictograms, the clip-art set of the vectorize benchmark.
APT_PACKAGES=(potrace libusb-1.0-0 libgl1 libgomp1 freecad-python3 freecad xvfb python3-scipy
              python3-pil python3-ezdxf fonts-font-awesome)
PYTHON=${PYTHON:-python3}
# Debian's own python3 needs python3-venv for `python3 -m venv` (ensurepip).
"$PYTHON" -c "import venv, ensurepip" 2>/dev/null || APT_PACKAGES+=(python3-venv)

missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "setup: installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
echo "setup: installing pde2cad and its dependencies into .venv (first time takes a few minutes)"
.venv/bin/python -m pip install -q -e ".[all,dev]"
.venv/bin/python -c "import pde2cad, numpy, scipy, ezdxf, OCP, build123d, cadquery, open3d; print('setup: pde2cad', pde2cad.__version__, 'ready')"

# The FreeCAD workbench: freecad_addon linked into the user's Mod folder; the addon puts this
# repository's src/ on FreeCAD's sys.path itself, so the core needs no install there.
mod="$HOME/.local/share/FreeCAD/Mod"
mkdir -p "$mod"
if [ -e "$mod/pde2cad" ] && [ ! -L "$mod/pde2cad" ]; then
  echo "setup: $mod/pde2cad exists and is not our link; leaving it (remove it to link this addon)"
else
  ln -sfn "$(pwd)/freecad_addon" "$mod/pde2cad"
  echo "setup: FreeCAD workbench linked: $mod/pde2cad -> $(pwd)/freecad_addon"
fi

if [ "${1:-}" = "--install-only" ]; then
  exit 0
fi

mkdir -p out
echo "setup: main job: reconstructing the labelled sample clouds in examples/clouds -> out/ (STEP, IGES, report, preview)"
for cloud in examples/clouds/*.ply; do
  name=$(basename "$cloud" .ply)
  .venv/bin/pde2cad reconstruct "$cloud" -o "out/$name.step" --iges "out/$name.igs" \
    --continuity c1 --report "out/$name.json" --preview "out/$name.png"
done
echo "setup: vectorizing the sample images in examples/images -> out/"
for img in examples/images/*.png; do
  name=$(basename "$img" .png)
  .venv/bin/pde2cad vectorize "$img" -o "out/$name.svg" -o "out/$name.dxf" --report "out/$name.json"
done
echo "setup: done; outputs are in $(pwd)/out"
