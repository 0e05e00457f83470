"""Open edges of a labelled cloud on the true rim (issue 13.3), through ``fit_surfaces``.

The open rims of the bundled tube and sheet (``pde2cad.samples``, random samples) used to be
fitted to the alpha-shape loop, about half a spacing inside the rim: 4.0e-3 and 2.4e-3 of the
diagonal on average. Fitted to the rim estimated from all samples near them they measure
1.2e-3 and 3.4e-4; the surfaces themselves keep their distance to the truth.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad import samples
from pde2cad.reconstruct import fit_surfaces


def _rim_error(name: str, q: NDArray[np.float64]) -> NDArray[np.float64]:
    if name == "cylinder":  # radius 1, z in [0, 2]
        return np.minimum(np.abs(q[:, 2]), np.abs(q[:, 2] - 2.0))
    # sheet over [0, 2]^2
    return np.minimum.reduce([np.abs(q[:, 0]), np.abs(q[:, 0] - 2), np.abs(q[:, 1]), np.abs(q[:, 1] - 2)])


@pytest.mark.parametrize(
    ("name", "rim_mean", "rim_max", "surface_mean"),
    [
        # Measured: rim mean 1.16e-3, max 3.4e-3, surface 1.8e-6 (loop: 4.0e-3, 9.8e-3, 2.1e-6).
        ("cylinder", 2.0e-3, 6e-3, 5e-6),
        # Measured: rim mean 3.4e-4, max 1.6e-3, surface 3.3e-7 (loop: 2.4e-3, 8.6e-3, 6.7e-7).
        ("sheet", 8e-4, 4e-3, 2e-6),
    ],
)
def test_open_edges_lie_on_the_true_rim(
    name: str, rim_mean: float, rim_max: float, surface_mean: float
) -> None:
    cloud = getattr(samples, name)()
    model = fit_surfaces(cloud.points, cloud.labels, continuity="c1")
    net = model.network
    rims = [
        _rim_error(name, net.curves[key].evaluate(np.linspace(0.0, 1.0, 200)))
        for key, users in net.users.items()
        if len(users) == 1
    ]
    assert len(rims) == 8  # tube: 4 sectors x 2 rims; sheet: 2 x 2 patches, 2 rims each
    err = np.concatenate(rims) / cloud.diagonal
    assert err.mean() <= rim_mean and err.max() <= rim_max
    g = np.linspace(0.0, 1.0, 30)
    grid = []
    for s in model.surfaces.values():
        p, q = s.degree_u, s.degree_v
        u = s.knots_u[p] + g * (s.knots_u[-p - 1] - s.knots_u[p])
        v = s.knots_v[q] + g * (s.knots_v[-q - 1] - s.knots_v[q])
        grid.append(s.evaluate_grid(u, v).reshape(-1, 3))
    assert cloud.distance(np.vstack(grid)).mean() / cloud.diagonal <= surface_mean
