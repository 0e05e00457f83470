"""Run scripts inside real FreeCAD (``freecadcmd``, or the GUI under Xvfb) with the addon
installed the way ``./setup.sh`` installs it, and collect what they measured.

``freecadcmd script.py`` exits 0 even when the script raises, so each script is wrapped:
whatever it stores in ``out`` (plus ``out["error"]``, the traceback, if it failed) is written
to a JSON file that the test reads and asserts on.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import textwrap
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
ADDON = ROOT / "freecad_addon"

_PRELUDE = """\
import json, os, sys, traceback
ARGS = json.load(open({args!r}))
out = {{}}
def _main():
{body}
def _finish():
    with open({result!r}, "w") as fh:
        json.dump(out, fh, default=str)
"""
_CMD = """\
try:
    _main()
except BaseException:
    out["error"] = traceback.format_exc()
_finish()
"""
_GUI = """\
def _run():
    try:
        _main()
    except BaseException:
        out["error"] = traceback.format_exc()
    _finish()
    os._exit(0)
from PySide import QtCore
QtCore.QTimer.singleShot(200, _run)
"""


def _home(tmp_path: Path) -> Path:
    """A HOME whose FreeCAD Mod folder holds the addon as a symlink (as setup.sh makes it)."""
    home = tmp_path / "home"
    mod = home / ".local" / "share" / "FreeCAD" / "Mod"
    mod.mkdir(parents=True, exist_ok=True)
    link = mod / "pde2cad"
    if not link.exists():
        link.symlink_to(ADDON, target_is_directory=True)
    return home


class FreeCADRun:
    """Runs script bodies in FreeCAD; ``last_output`` keeps the process's console text."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp = tmp_path
        self.count = 0
        self.last_output = ""

    def __call__(self, body: str, gui: bool = False, timeout: float = 900, **args: Any) -> dict:
        self.count += 1
        script = self.tmp / f"fc_script_{self.count}.py"
        result = self.tmp / f"fc_result_{self.count}.json"
        args_file = self.tmp / f"fc_args_{self.count}.json"
        args_file.write_text(json.dumps(args, default=str))
        text = _PRELUDE.format(args=str(args_file), result=str(result),
                               body=textwrap.indent(textwrap.dedent(body), "    "))
        script.write_text(text + (_GUI if gui else _CMD))
        env = dict(os.environ, HOME=str(_home(self.tmp)), QTWEBENGINE_DISABLE_SANDBOX="1")
        env.pop("PYTHONPATH", None)  # FreeCAD's Python must not see the venv's packages
        cmd = (["xvfb-run", "-a", "-s", "-screen 0 1280x900x24", "freecad", str(script)]
               if gui else ["freecadcmd", str(script)])
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              cwd=self.tmp, env=env, check=False)
        self.last_output = proc.stdout + proc.stderr
        assert result.is_file(), f"FreeCAD wrote no result (exit {proc.returncode}):\n{self.last_output[-3000:]}"
        out = json.loads(result.read_text())
        assert "error" not in out, out["error"]
        return out


def _need_freecadcmd() -> None:
    if shutil.which("freecadcmd") is None:
        pytest.skip("FreeCAD 0.20 is not installed (apt-get install freecad-python3)")


@pytest.fixture
def freecad(tmp_path: Path) -> FreeCADRun:
    _need_freecadcmd()
    return FreeCADRun(tmp_path)


@pytest.fixture(scope="module")
def freecad_module(tmp_path_factory: pytest.TempPathFactory) -> FreeCADRun:
    """One runner (and folder) for a whole test module, to share one expensive run."""
    _need_freecadcmd()
    return FreeCADRun(tmp_path_factory.mktemp("freecad"))


@pytest.fixture
def freecad_gui(tmp_path: Path) -> FreeCADRun:
    if shutil.which("freecad") is None or shutil.which("xvfb-run") is None:
        pytest.skip("the FreeCAD GUI or Xvfb is not installed (apt-get install freecad xvfb)")
    return FreeCADRun(tmp_path)
