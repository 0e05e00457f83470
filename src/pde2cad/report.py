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
#: A read-back edge end is the network corner nearest to it when within this (x diagonal):
#: ten times the sewing tolerance (sewing may merge vertices up to that far apart).
CORNER_MATCH_TOLERANCE = 1e-5
#: An edge sample is "near" an irregular corner (one where three or five patches meet, where
#: G1 cannot be had by pairing edges) when its straight-line distance to that corner is at
#: most this fraction of the edge's length (the polyline through its samples) -- or one span
#: of the edge's curve when that is longer: the end span is the part of the seam that the
#: corner's ribbon construction controls, and the kink fills it (on the C1 six-patch sphere,
#: 4 spans per edge, it peaks at 12-15 % of the length and drops to ~0 at the span break).
#: Elsewhere the C1 construction applies and a smooth shape must show (almost) no kink.
NEAR_CORNER_FRACTION = 0.1
#: Samples per shared edge when measuring the read-back shape (the ends get the finest
#: look: with 40 uniform samples about four lie within 10 % of each end).
SEAM_SAMPLES = 40


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
    samples: int = SEAM_SAMPLES,
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
        in degrees, the network corners at its ends and its max normal angle away from and
        near irregular corners), ``corners`` (per network corner: position, valence, whether
        regular), ``patches`` (per label: points, terms, errors absolute and relative) and
        ``timings``.

    Notes
    -----
    Seam angles are split by the network's corners (``rec.network``). A corner is *irregular*
    when its edges do not pair up (``network.regular[c]`` false: three or five patches meet,
    e.g. the eight corners of a six-patch sphere); G1 there is the vertex-enclosure problem and
    a kink near it is expected. A sample of a shared edge is *near* an irregular corner when its
    distance to it is at most ``NEAR_CORNER_FRACTION`` (10 %) of the edge's length, or one span
    of the edge's curve (``network.spans``) when longer (per edge ``near_fraction``). The summary
    gives ``max_angle_deg_regular`` over all other samples (on a smooth shape fitted C1 this is
    the number that should be ~0; None if every sample is near one) and
    ``max_angle_deg_near_irregular_corners`` (None when there is no such sample), with ``irregular_corners``, ``corner_valences`` (patches meeting at a
    corner -> how many corners) and ``c0_fallback``. Read-back edge ends are matched to the
    network corners by position (``CORNER_MATCH_TOLERANCE`` x diagonal); ``corners_matched``
    says whether every end found its corner. Without a network all these are None.
    """
    from pde2cad.occ import measure, read_step
    from pde2cad.occ.probe import face_centres

    shape = read_step(step_path, units=units)
    m = measure(shape, samples=samples, profile=True)
    diagonal = float(rec.diagonal) if rec.diagonal > 0 else 1.0
    labels = [int(label) for label in rec.labels]
    face_labels, worst = match_faces(
        face_centres(shape), surface_centres(rec.surfaces, labels), labels
    )
    matched = worst <= MATCH_TOLERANCE * diagonal and len(face_labels) == len(labels)

    network = getattr(rec, "network", None)
    corners = corner_info(network)
    irregular = np.array(
        [c["xyz"] for c in corners if not c["regular"]], dtype=float
    ).reshape(-1, 3)
    corner_xyz = np.array([c["xyz"] for c in corners], dtype=float).reshape(-1, 3)

    edges = []
    split = _AngleSplit()
    worst_corner = 0.0
    for e in m["edges"]:
        i, j = e["faces"]
        pair = [face_labels[i], face_labels[j]]
        if all(p is not None for p in pair):
            pair = sorted(pair)
        entry: dict[str, Any] = {
            "labels": pair,
            "faces": [int(i), int(j)],
            "max_gap": float(e["max_gap"]),
            "max_gap_rel": float(e["max_gap"]) / diagonal,
            "max_angle_deg": float(e["max_angle_deg"]),
        }
        if network is not None:
            points = np.asarray(e["profile"]["points"], dtype=float)
            angles = np.asarray(e["profile"]["angles_deg"], dtype=float)
            ends, dist = match_corners(
                points[[0, -1]], corner_xyz, CORNER_MATCH_TOLERANCE * diagonal
            )
            worst_corner = max(worst_corner, dist)
            fraction = NEAR_CORNER_FRACTION
            a, b = ends
            if a is not None and b is not None:
                spans = (getattr(network, "spans", None) or {}).get((min(a, b), max(a, b)))
                if spans:
                    fraction = max(fraction, 1.0 / int(spans))
            near = near_corners(points, irregular, fraction)
            entry["corners"] = ends
            entry["near_fraction"] = fraction
            entry["max_angle_deg_regular"] = _nanmax(angles[~near])
            entry["max_angle_deg_near_irregular"] = _nanmax(angles[near])
            # A crease keeps its kink: its angle is the part's dihedral, not a seam error.
            entry["crease"] = bool(a is not None and b is not None
                                   and (min(a, b), max(a, b)) in (getattr(network, "creases", None) or set()))
            finite = angles[~np.isnan(angles)]
            entry["min_angle_deg"] = float(finite.min()) if len(finite) else None
            if not entry["crease"]:
                split.add(entry)
        edges.append(entry)
    edges.sort(key=lambda e: (e["labels"][0] is None, e["labels"]))

    patches = []
    for label in labels:
        patch = rec.patches[label]
        quick = None if orthogonal else getattr(patch, "fit_errors", None)
        err = patch.errors if quick is None else quick
        row: dict[str, Any] = {
            "label": label,
            "points": int(len(patch.points)),
            "sides": int(len(patch.sides)),
            "terms": [int(patch.m), int(patch.n)],
        }
        for key in ("mean", "max", "rms", "mean_orthogonal", "max_orthogonal"):
            if key in err:
                row[key] = float(err[key])
                row[f"{key}_rel"] = float(err[key]) / diagonal
        patches.append(row)

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
        "seam_samples": int(samples),
        "valid": bool(m["valid"]),
        "closed": bool(m["closed"]),
        "solid": bool(info.is_solid),
        "diagonal": float(rec.diagonal),
        "mean_error_rel": max((p.get("mean_rel", 0.0) for p in patches), default=0.0),
        "max_error_rel": max((p.get("max_rel", 0.0) for p in patches), default=0.0),
        "faces_matched": bool(matched),
        "face_match_distance": float(worst),
        "c0_fallback": sorted(int(label) for label in getattr(rec, "c0_fallback", None) or []),
        "splits": {
            str(label): [int(p) for p in pieces]
            for label, pieces in getattr(getattr(rec, "splits", None), "pieces", {}).items()
        },
        "merged": {
            str(b): int(a)
            for b, a in getattr(getattr(rec, "splits", None), "merged", {}).items()
        },
        **_corner_summary(network, corners, split, worst_corner, diagonal),
        **_crease_summary(edges if network is not None else None),
    }
    all_timings = {k: float(v) for k, v in getattr(rec, "timings", {}).items()}
    all_timings.update({k: float(v) for k, v in (timings or {}).items()})
    return {
        "input": dict(input_info or {}),
        "settings": dict(settings or {}),
        "summary": summary,
        "edges": edges,
        "corners": corners,
        "patches": patches,
        "timings": all_timings,
    }


def corner_info(network: Any) -> list[dict[str, Any]]:
    """Per network corner: ``id``, ``xyz``, ``valence`` (patches whose side loop passes
    through it) and ``regular`` (its edges pair up; see :class:`EdgeNetwork`)."""
    if network is None:
        return []
    xyz = np.asarray(network.corners, dtype=float).reshape(-1, 3)
    valence = np.zeros(len(xyz), dtype=int)
    for ids in network.loops.values():
        for c in set(int(c) for c in ids):
            valence[c] += 1
    return [
        {
            "id": c,
            "xyz": [float(v) for v in xyz[c]],
            "valence": int(valence[c]),
            "regular": bool(network.regular.get(c, True)),
        }
        for c in range(len(xyz))
    ]


def match_corners(
    ends: NDArray[np.float64], corners: NDArray[np.float64], tolerance: float
) -> tuple[list[int | None], float]:
    """The corner id nearest each of ``ends`` (None when farther than ``tolerance``), and the
    largest nearest distance."""
    if len(corners) == 0:
        return [None] * len(ends), 0.0
    dist = np.linalg.norm(ends[:, None, :] - corners[None, :, :], axis=2)
    nearest = dist.argmin(axis=1)
    best = dist[np.arange(len(ends)), nearest]
    ids = [int(c) if d <= tolerance else None for c, d in zip(nearest, best, strict=True)]
    return ids, float(best.max()) if len(best) else 0.0


def near_corners(
    points: NDArray[np.float64], corners: NDArray[np.float64], fraction: float
) -> NDArray[np.bool_]:
    """Which of an edge's sample ``points`` (in order along it) lie within ``fraction`` of the
    edge's length (polyline through the samples) of any of ``corners``."""
    if len(corners) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    dist = np.linalg.norm(points[:, None, :] - corners[None, :, :], axis=2).min(axis=1)
    return np.asarray(dist <= fraction * length)


def _nanmax(values: NDArray[np.float64]) -> float | None:
    finite = values[~np.isnan(values)]
    return float(finite.max()) if len(finite) else None


class _AngleSplit:
    """Running maxima of the per-edge split angles."""

    def __init__(self) -> None:
        self.regular: float | None = None
        self.near: float | None = None

    def add(self, edge: Mapping[str, Any]) -> None:
        for attr, key in (("regular", "max_angle_deg_regular"),
                          ("near", "max_angle_deg_near_irregular")):  # fmt: skip
            value = edge[key]
            if value is not None:
                old = getattr(self, attr)
                setattr(self, attr, value if old is None else max(old, value))


def _corner_summary(
    network: Any, corners: list[dict[str, Any]], split: _AngleSplit, worst: float,
    diagonal: float,
) -> dict[str, Any]:
    if network is None:
        return {
            "irregular_corners": None, "corner_valences": None, "irregular_valences": None,
            "max_angle_deg_regular": None, "max_angle_deg_near_irregular_corners": None,
            "corners_matched": None, "corner_match_distance": None,
        }  # fmt: skip
    valences: dict[str, int] = {}
    irregular: dict[str, int] = {}
    for c in sorted(corners, key=lambda c: c["valence"]):
        key = str(c["valence"])
        valences[key] = valences.get(key, 0) + 1
        if not c["regular"]:
            irregular[key] = irregular.get(key, 0) + 1
    return {
        "irregular_corners": sum(irregular.values()),
        "corner_valences": valences,
        "irregular_valences": irregular,
        # None when every seam sample is near an irregular corner; 0 without shared edges.
        "max_angle_deg_regular": (
            split.regular if split.regular is not None or split.near is not None else 0.0
        ),
        "max_angle_deg_near_irregular_corners": split.near,
        "corners_matched": bool(worst <= CORNER_MATCH_TOLERANCE * diagonal),
        "corner_match_distance": float(worst),
    }


def _crease_summary(edges: list[dict[str, Any]] | None) -> dict[str, Any]:
    """Shared edges the network keeps sharp (creases): how many, the range of the normal
    angle across them (the part's dihedral as built), and the largest angle across the
    other (smooth) seams. All None without a network."""
    if edges is None:
        return {"crease_edges": None, "crease_angle_deg": None, "max_angle_deg_smooth": None}
    creases = [e for e in edges if e.get("crease")]
    smooth = [e["max_angle_deg"] for e in edges if not e.get("crease")]
    lows = [e["min_angle_deg"] for e in creases if e.get("min_angle_deg") is not None]
    return {
        "crease_edges": len(creases),
        "crease_angle_deg": ([min(lows), max(e["max_angle_deg"] for e in creases)]
                             if creases and lows else None),
        "max_angle_deg_smooth": max(smooth, default=0.0),
    }


#: Patches with fewer points than this get a note in the summary (measured: 500-800 points
#: per patch can fold faces near three-patch corners; from ~1000 the samples were reliable).
SPARSE_PATCH = 1000


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
    span = s.get("crease_angle_deg")
    if s.get("crease_edges") and span:
        lines.append(f"creases: {s['crease_edges']} edges kept sharp, normal angle across them "
                     f"{span[0]:.3g}-{span[1]:.3g} deg; smooth seams max {s['max_angle_deg_smooth']:.3g} deg")
    seams = "smooth seams" if s.get("crease_edges") else "seams"
    irregular = s.get("irregular_corners")
    if irregular:
        near = s.get("max_angle_deg_near_irregular_corners")
        near_text = "n/a" if near is None else f"{near:.2g} deg"
        away = s.get("max_angle_deg_regular")
        away_text = "n/a" if away is None else f"{away:.3f} deg"
        lines.append(
            f"{seams}: max normal angle {away_text} away from "
            f"{_corner_kinds(s.get('irregular_valences') or {}, irregular)}, "
            f"{near_text} near them"
        )
    elif irregular == 0 and s.get("corner_valences") and _c1(report):
        # Only worth a line with C1: the angle is then the one that must stay ~0.
        lines.append(
            f"{seams}: every corner regular (four patches, or two at the open boundary), "
            f"max normal angle {s['max_angle_deg_regular']:.3f} deg"
        )
    if s.get("corners_matched") is False:
        lines.append(
            "note: read-back edge ends could not all be matched to network corners "
            f"(off by {s['corner_match_distance']:.3g}); the near-corner split may be off"
        )
    for label, into in (s.get("merged") or {}).items():
        lines.append(f"split: segment {label} merged into {into} (they meet along two borders)")
    for label, pieces in (s.get("splits") or {}).items():
        lines.append(
            f"split: segment {label} (not 3- or 4-sided) -> {len(pieces)} patches "
            f"{', '.join(map(str, pieces))}"
        )
    fallback = s.get("c0_fallback") or []
    if fallback:
        word = "patch" if len(fallback) == 1 else "patches"
        lines.append(
            f"C1: {word} {', '.join(map(str, fallback))} kept C0 (3-sided or their C1 fit "
            "was worse)"
        )
    patches = report.get("patches") or []
    sparse = [p for p in patches if p.get("points", SPARSE_PATCH) < SPARSE_PATCH]
    if sparse:
        fewest = min(sparse, key=lambda p: p["points"])
        lines.append(
            f"note: {len(sparse)} of {len(patches)} patches have fewer than "
            f"{SPARSE_PATCH} points (segment {fewest['label']}: {fewest['points']}); below "
            "that, edges and corners get noisy and faces may fold near corners — scan denser "
            "or merge segments"
        )
    if not s["faces_matched"]:
        lines.append(
            "note: read-back faces could not all be matched to segments "
            f"(off by {s['face_match_distance']:.3g}); edge labels may be missing"
        )
    return lines


def _c1(report: Mapping[str, Any]) -> bool:
    settings = report.get("settings") or {}
    return str(settings.get("continuity", "")).lower() == "c1"


_COUNT_WORDS = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}


def _corner_kinds(valences: Mapping[str, int], total: int) -> str:
    """E.g. ``"8 three-patch corners"`` or ``"4 three-patch and 2 five-patch corners"``."""
    parts = [
        f"{count} {_COUNT_WORDS.get(int(v), v)}-patch"
        for v, count in sorted(valences.items(), key=lambda kv: int(kv[0]))
    ]
    if not parts:
        return f"{total} irregular corners"
    text = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return text + (" corner" if total == 1 else " corners")


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


__all__ = [
    "build_report",
    "corner_info",
    "json_safe",
    "match_corners",
    "match_faces",
    "near_corners",
    "summary_lines",
    "surface_centres",
]
