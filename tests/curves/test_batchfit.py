"""The batched Levenberg-Marquardt fit: each problem's fit does not depend on its batch."""

from __future__ import annotations

import numpy as np

from pde2cad.curves import batchfit


def _problems(n_problems=6, n=40, seed=3):
    """Noisy arcs of different bends, some easy (converge in a round or two), some hard."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, n)
    pts = np.stack([np.c_[30 * u, (4 * k) * np.sin(np.pi * u * (1 + k / 3))] + rng.normal(0, 0.3, (n, 2))
                    for k in range(n_problems)])
    tan = np.tile([1.0, 0.0], (n_problems, 1))
    return batchfit.Batch(pts, np.ones((n_problems, n), bool), pts[:, 0].copy(), pts[:, -1].copy(), tan, tan.copy()), np.tile(u, (n_problems, 1))


def test_each_problem_fits_as_if_alone():
    # Retries recompute only the problems still pending: a problem that converges (or
    # stops improving) must not change the others' fits, nor theirs its own.
    batch, t = _problems()
    ctrl, t_all, err = batchfit.fit_batch(batch, t.copy(), 5)
    for i in range(len(t)):
        one = batchfit.Batch(*(None if a is None else a[i : i + 1] for a in
                               (batch.points, batch.valid, batch.p0, batch.p3, batch.tan0, batch.tan3)))
        c1, t1, e1 = batchfit.fit_batch(one, t[i : i + 1].copy(), 5)
        assert np.abs(c1[0] - ctrl[i]).max() < 1e-9
        assert np.abs(e1[0] - err[i]).max() < 1e-9

