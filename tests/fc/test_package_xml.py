"""The repository root carries Addon Manager metadata pointing at ``freecad_addon/``, so the
Addon Manager (which reads ``package.xml`` at the root of what it clones) can install the
workbench straight from this repository."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NS = {"p": "https://wiki.freecad.org/Package_Metadata"}


def _workbench(xml: Path) -> tuple[ET.Element, ET.Element]:
    root = ET.parse(xml).getroot()
    bench = root.find("p:content/p:workbench", NS)
    assert bench is not None
    return root, bench


def test_root_package_xml_points_at_the_addon() -> None:
    root, bench = _workbench(ROOT / "package.xml")
    sub = ROOT / bench.findtext("p:subdirectory", namespaces=NS)
    assert (sub / "freecad" / "pde2cad" / "init_gui.py").is_file()
    assert (ROOT / root.findtext("p:icon", namespaces=NS)).is_file()
    classname = bench.findtext("p:classname", namespaces=NS)
    assert re.search(rf"class {classname}\b", (sub / "freecad/pde2cad/init_gui.py").read_text())


def test_root_and_addon_metadata_agree() -> None:
    top, bench = _workbench(ROOT / "package.xml")
    inner, inner_bench = _workbench(ROOT / "freecad_addon" / "package.xml")
    for tag in ("p:name", "p:version", "p:description"):
        assert top.findtext(tag, namespaces=NS) == inner.findtext(tag, namespaces=NS)
    deps = lambda b: sorted(d.text or "" for d in b.findall("p:depend", NS))  # noqa: E731
    assert deps(bench) == deps(inner_bench)
