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



def test_mixed_end_constraints_fit_as_their_own_kind():
    # Rows of NaN tangents free that end for that problem only: one batch of all four kinds
    # (free/free, G1/free, free/G1, G1/G1) gives each problem the fit of a batch of its kind
    # (issue 11: one batch instead of one per kind).
    batch, t = _problems(n_problems=8)
    free0, free3 = np.arange(8) % 2 == 0, np.arange(8) % 4 < 2
    tan0, tan3 = batch.tan0.copy(), batch.tan3.copy()
    tan0[free0], tan3[free3] = np.nan, np.nan
    mixed = batchfit.Batch(batch.points, batch.valid, batch.p0, batch.p3, tan0, tan3)
    ctrl, _, err = batchfit.fit_batch(mixed, t.copy(), 5)
    for i in range(8):
        one = batchfit.Batch(batch.points[i : i + 1], batch.valid[i : i + 1], batch.p0[i : i + 1], batch.p3[i : i + 1],
                             None if free0[i] else batch.tan0[i : i + 1], None if free3[i] else batch.tan3[i : i + 1])
        c1, _, e1 = batchfit.fit_batch(one, t[i : i + 1].copy(), 5)
        assert np.abs(c1[0] - ctrl[i]).max() < 1e-6
        assert np.abs(e1[0] - err[i]).max() < 1e-6
        if not free0[i]:  # the G1 end keeps its direction
            d = ctrl[i, 1] - ctrl[i, 0]
            assert abs(d[1]) < 1e-9 and d[0] > 0
