"""Continuity and accuracy report of a multi-patch reconstruction, checked on the written file.

The report is built from what a CAD system will see: the STEP file is read back and measured
(:func:`~pde2cad.occ.continuity.measure`), so gaps and kinks include everything the export
did to the geometry. Read-back faces are matched to segment labels by position (a round
trip may reorder faces), then every shared edge is reported by the labels of its two faces.

OCP is imported inside the functions that need it, so importing this module stays cheap.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: A read-back face whose centre is farther than this (x diagonal) from every fitted
#: surface's centre is not one of ours: the matching is then reported as unreliable.
MATCH_TOLERANCE = 1e-4


def surface_centres(surfaces: Mapping[int, Any], labels: Sequence[int]) -> NDArray[np.float64]:
    """The point at the middle of each surface's knot domain, in ``labels`` order."""
    out = np.empty((len(labels), 3))
    for i, label in enumerate(labels):
        s = surfaces[label]
        u = 0.5 * (float(s.knots_u[0]) + float(s.knots_u[-1]))
        v = 0.5 * (float(s.knots_v[0]) + float(s.knots_v[-1]))
        out[i] = np.asarray(s.evaluate(np.array([u]), np.array([v])), dtype=float).reshape(-1)[:3]
    return out


def match_faces(
    face_points: NDArray[np.float64], label_points: NDArray[np.float64], labels: Sequence[int]
) -> tuple[list[int | None], float]:
    """Assign a segment label to each read-back face by the nearest surface centre.

    Parameters
    ----------
    face_points : (F, 3) float
        One probe point per read-back face (see :func:`pde2cad.occ.probe.face_centres`).
    label_points : (L, 3) float
        The same probe point of each fitted surface, in ``labels`` order.
    labels : sequence of int

    Returns
    -------
    face_labels : list of int or None
        Label of each face; ``None`` for faces left over when ``F > L``.
    worst : float
        Largest distance between a matched face point and its surface point.

    Notes
    -----
    A one-to-one assignment (Hungarian method), not a per-face nearest neighbour: two faces
    can never claim the same label.
    """
    from scipy.optimize import linear_sum_assignment

    face_labels: list[int | None] = [None] * len(face_points)
    if len(face_points) == 0 or len(label_points) == 0:
        return face_labels, 0.0
    cost = np.linalg.norm(face_points[:, None, :] - label_points[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(cost)
    for r, c in zip(rows, cols, strict=True):
        face_labels[int(r)] = int(labels[int(c)])
    return face_labels, float(cost[rows, cols].max())


def build_report(
    rec: Any,
    step_path: str | Path,
    *,
    units: str = "MM",
    input_info: Mapping[str, Any] | None = None,
    settings: Mapping[str, Any] | None = None,
    timings: Mapping[str, float] | None = None,
    samples: int = 20,
    orthogonal: bool = True,
) -> dict[str, Any]:
    """Read ``step_path`` back, measure it and describe the reconstruction ``rec``.

    Parameters
    ----------
    rec : Reconstruction
        The result of :func:`pde2cad.reconstruct.reconstruct` that was written.
    step_path : str or Path
        The STEP file written from ``rec.shape``.
    units : str
        Unit the file was written in (read back in the same unit, so no scaling).
    input_info, settings : mapping, optional
        Copied into the report as ``"input"`` and ``"settings"``.
    timings : mapping, optional
        Extra stage times (seconds), merged over ``rec.timings``.
    samples : int
        Points per edge for :func:`~pde2cad.occ.continuity.measure`.
    orthogonal : bool
        Include each patch's orthogonal errors (``mean_orthogonal``, ``max_orthogonal``),
        which project every point onto its surface once more (about as long as a fit);
        False leaves them out, e.g. when only the summary is shown.

    Returns
    -------
    dict
        JSON-serialisable: ``input``, ``settings``, ``summary``, ``edges`` (per shared edge:
        the two face labels, max gap absolute and relative to the diagonal, max normal angle
        in degrees), ``patches`` (per label: points, terms, errors absolute and relative) and
        ``timings``.
    """
    from pde2cad.occ import measure, read_step
    from pde2cad.occ.probe import face_centres

    shape = read_step(step_path, units=units)
    m = measure(shape, samples=samples)
    diagonal = float(rec.diagonal) if rec.diagonal > 0 else 1.0
    labels = [int(label) for label in rec.labels]
    face_labels, worst = match_faces(
        face_centres(shape), surface_centres(rec.surfaces, labels), labels
    )
    matched = worst <= MATCH_TOLERANCE * diagonal and len(face_labels) == len(labels)

    edges = []
    for e in m["edges"]:
        i, j = e["faces"]
        pair = [face_labels[i], face_labels[j]]
        if all(p is not None for p in pair):
            pair = sorted(pair)  # type: ignore[type-var]
        edges.append(
            {
                "labels": pair,
                "faces": [int(i), int(j)],
                "max_gap": float(e["max_gap"]),
                "max_gap_rel": float(e["max_gap"]) / diagonal,
                "max_angle_deg": float(e["max_angle_deg"]),
            }
        )
    edges.sort(key=lambda e: (e["labels"][0] is None, e["labels"]))

    patches = []
    for label in labels:
        patch = rec.patches[label]
        quick = None if orthogonal else getattr(patch, "fit_errors", None)
        err = patch.errors if quick is None else quick
        entry: dict[str, Any] = {
            "label": label,
            "points": int(len(patch.points)),
            "sides": int(len(patch.sides)),
            "terms": [int(patch.m), int(patch.n)],
        }
        for key in ("mean", "max", "rms", "mean_orthogonal", "max_orthogonal"):
            if key in err:
                entry[key] = float(err[key])
                entry[f"{key}_rel"] = float(err[key]) / diagonal
        patches.append(entry)

    info = rec.sew_info
    summary = {
        "n_faces": int(m["n_faces"]),
        "n_shells": int(m["n_shells"]),
        "shared_edges": int(m["shared_edges"]),
        "free_edges": int(m["free_edges"]),
        "nonmanifold_edges": int(m["nonmanifold_edges"]),
        "max_gap": float(m["max_gap"]),
        "max_gap_rel": float(m["max_gap"]) / diagonal,
        "max_angle_deg": float(m["max_angle_deg"]),
        "valid": bool(m["valid"]),
        "closed": bool(m["closed"]),
        "solid": bool(info.is_solid),
        "diagonal": float(rec.diagonal),
        "mean_error_rel": max((p.get("mean_rel", 0.0) for p in patches), default=0.0),
        "max_error_rel": max((p.get("max_rel", 0.0) for p in patches), default=0.0),
        "faces_matched": bool(matched),
        "face_match_distance": float(worst),
    }
    all_timings = {k: float(v) for k, v in getattr(rec, "timings", {}).items()}
    all_timings.update({k: float(v) for k, v in (timings or {}).items()})
    return {
        "input": dict(input_info or {}),
        "settings": dict(settings or {}),
        "summary": summary,
        "edges": edges,
        "patches": patches,
        "timings": all_timings,
    }


def summary_lines(report: Mapping[str, Any]) -> list[str]:
    """A few human-readable lines of a :func:`build_report` dict."""
    s = report["summary"]
    kind = "solid" if s["solid"] else ("closed shell" if s["closed"] else "open shell")
    shells = f"{s['n_shells']} shells, " if s["n_shells"] != 1 else ""
    lines = [
        f"{s['n_faces']} faces, {shells}{kind}, {'valid' if s['valid'] else 'INVALID'}, "
        f"{s['shared_edges']} shared and {s['free_edges']} free edges",
        f"seams: max gap {s['max_gap']:.3g} ({s['max_gap_rel']:.2g} x diagonal), "
        f"max normal angle {s['max_angle_deg']:.3g} deg",
        f"fit: worst patch mean error {s['mean_error_rel']:.2g} x diagonal, "
        f"max {s['max_error_rel']:.2g} x diagonal (diagonal {s['diagonal']:.4g})",
    ]
    if not s["faces_matched"]:
        lines.append(
            "note: read-back faces could not all be matched to segments "
            f"(off by {s['face_match_distance']:.3g}); edge labels may be missing"
        )
    return lines


def json_safe(value: Any) -> Any:
    """``value`` with NaN/inf floats replaced by ``None`` (JSON has no spelling for them) and
    numpy scalars and tuples turned into plain Python numbers and lists."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(float(value)) else None
    return value


__all__ = ["build_report", "json_safe", "match_faces", "summary_lines", "surface_centres"]
