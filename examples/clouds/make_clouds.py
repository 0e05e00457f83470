"""Write the bundled labelled sample clouds (binary PLY, label in ``scalar_label``).

Run from the project root: ``.venv/bin/python examples/clouds/make_clouds.py``. Each cloud is
sampled uniformly at random by area from an analytic shape of :mod:`pde2cad.samples` (seed 0),
one label per patch, so ``pde2cad reconstruct examples/clouds/NAME.ply -o NAME.step`` works
without ``--labels``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pde2cad import samples
from pde2cad.io.atomic import atomic_path

HERE = Path(__file__).resolve().parent
CLOUDS = {
    "torus": lambda: samples.torus(20000),
    "sphere6": lambda: samples.sphere6(20000),
    "cylinder": lambda: samples.cylinder(20000),
    "can": lambda: samples.can(20000),
    "pot": lambda: samples.pot(20000),
    "torus_noisy": lambda: samples.torus(20000, noise=0.003),
}


def write_ply(path: Path, points: np.ndarray, labels: np.ndarray) -> None:
    """Binary little-endian PLY: float x, y, z and int scalar_label per vertex."""
    rows = np.zeros(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("label", "<i4")])
    rows["x"], rows["y"], rows["z"] = points.T
    rows["label"] = labels
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(points)}\n"
        "property float x\nproperty float y\nproperty float z\nproperty int scalar_label\n"
        "end_header\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_bytes(header.encode("ascii") + rows.tobytes())


def main() -> None:
    for name, make in CLOUDS.items():
        cloud = make()
        write_ply(HERE / f"{name}.ply", cloud.points, cloud.labels)
        print(f"{name}.ply: {len(cloud.points)} points, {len(np.unique(cloud.labels))} patches")


if __name__ == "__main__":
    main()
