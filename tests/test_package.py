"""Package-level promises: light import, core math free of CAD kernels."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

import pde2cad

HEAVY = ("OCP", "FreeCAD", "ezdxf", "open3d", "matplotlib", "cadquery", "build123d")


def test_core_imports_no_cad_kernel_or_plotting():
    code = (
        "import sys, pde2cad\n"
        "import pde2cad.image.vectorize, pde2cad.curves.piecewise, pde2cad.surfaces.coons\n"
        "import pde2cad.surfaces.deformation, pde2cad.surfaces.projection\n"
        "import pde2cad.surfaces.pde_closed_form\n"
        f"bad = [m for m in {HEAVY!r} if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_public_api_names():
    for name in ("vectorize", "fit_patch", "fit_pde_surface", "InputError", "FitError", "__version__"):
        assert hasattr(pde2cad, name)
    assert issubclass(pde2cad.InputError, ValueError)


def test_fit_pde_surface_through_the_package_on_the_nose_data():
    path = Path(__file__).resolve().parents[1] / "examples" / "data" / "nose16.csv"
    data = np.loadtxt(path, delimiter=",", comments="#", skiprows=3)
    pts = data[:, 2:5]
    uv = np.c_[data[:, 1] / 3.0, data[:, 0] / 3.0]
    surf = pde2cad.fit_pde_surface(pts, uv, solution="X4", terms=16)
    assert surf.errors["max"] <= 5.52e-5  # Table 4.2
    assert surf.errors["mean"] <= 2.31e-5


def test_vectorize_path_loads_no_scipy(tmp_path):
    """One small image through the CLI (tracing with holes, corners, symmetry, distances)
    must not import scipy: its import alone costs 0.3-0.5 s of a 0.5 s budget."""
    code = (
        "import sys, numpy as np\n"
        "from PIL import Image\n"
        "yy, xx = np.mgrid[0:120, 0:120] + 0.5\n"
        "r = np.hypot(xx - 60.3, yy - 59.6)\n"
        "ring = (r < 40 + 8 * np.cos(5 * np.arctan2(yy - 59.6, xx - 60.3))) & (r > 15)\n"
        f"Image.fromarray(np.where(ring, 0, 255).astype(np.uint8)).save({str(tmp_path / 'r.png')!r})\n"
        "from pde2cad.cli import main\n"
        f"assert main(['vectorize', {str(tmp_path / 'r.png')!r}, '-o', {str(tmp_path / 'r.svg')!r}]) == 0\n"
        "bad = [m for m in sys.modules if m.split('.')[0] == 'scipy']\n"
        "assert not bad, bad[:5]\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "r.svg").read_text().count("<path") >= 1
