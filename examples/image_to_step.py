"""Image -> extruded solid -> STEP: a 0.1 mm/px plate outline extruded 5 mm (build123d)."""
from pathlib import Path

import build123d as bd

import pde2cad

drawing = pde2cad.vectorize(Path(__file__).parent / "images/holes_keyhole_plate.png", scale=0.1)
plate = bd.extrude(drawing.to_build123d(), amount=5)
pde2cad.export_step(plate, "plate.step", author="pde2cad example")
