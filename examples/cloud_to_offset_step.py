"""Cloud -> build123d solid -> offset by 1 % of its size -> STEP (the bundled sphere cloud)."""
from pathlib import Path

import build123d as bd

import pde2cad
from pde2cad.io.clouds import read_cloud

points, labels = read_cloud(Path(__file__).parent / "clouds/sphere6.ply", labels="scalar_label")
ball = pde2cad.to_build123d(pde2cad.reconstruct(points, labels, continuity="c1"))
pde2cad.export_step(bd.offset(ball, 0.03, kind=bd.Kind.ARC), "ball_offset.step")
