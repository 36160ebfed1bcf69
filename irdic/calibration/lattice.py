"""Automatic marker correspondence for targets with markers on planar grids (open book).

See :func:`match_lattice`.
"""

from __future__ import annotations

import itertools
import logging

import numpy as np
from scipy.spatial import cKDTree

from ..camera import CameraModel, dlt
from ..errors import CalibrationError
from .bias import find_planes
from .correspondence import SEEDS_HINT, propagate, reprojection_rms

__all__ = ["match_lattice"]

log = logging.getLogger(__name__)

# -- automatic correspondence for grid targets


def _homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Normalised DLT homography src -> dst (both (n, 2), n >= 4)."""

    def norm(p):
        c = p.mean(axis=0)
        s = np.sqrt(2) / max(np.sqrt(((p - c) ** 2).sum(axis=1)).mean(), 1e-12)
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])

    Ts, Td = norm(src), norm(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    n = len(s)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = s, 1
    A[0::2, 6:8], A[0::2, 8] = -d[:, :1] * s, -d[:, 0]
    A[1::2, 3:5], A[1::2, 5] = s, 1
    A[1::2, 6:8], A[1::2, 8] = -d[:, 1:] * s, -d[:, 1]
    _, _, vt = np.linalg.svd(A)
    H = np.linalg.solve(Td, vt[-1].reshape(3, 3)) @ Ts
    return H / H[2, 2]


def _apply_h(H: np.ndarray, p: np.ndarray) -> np.ndarray:
    h = p @ H[:, :2].T + H[:, 2]
    return h[:, :2] / h[:, 2:3]


def _grow_lattice(uv: np.ndarray, free: np.ndarray, quad: list[int], tol: float = 0.2) -> dict[int, tuple]:
    """Detections (indices into uv, among ``free``) on the planar lattice started by a unit quad."""
    nodes = {quad[0]: (0, 0), quad[1]: (1, 0), quad[2]: (0, 1), quad[3]: (1, 1)}
    for _ in range(60):
        ids = np.array(list(nodes))
        ij = np.array([nodes[i] for i in ids], dtype=np.float64)
        H = _homography(ij, uv[ids])
        try:
            Hi = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return nodes
        cand = free[~np.isin(free, ids)]
        if len(cand) == 0:
            break
        st = _apply_h(Hi, uv[cand])
        rnd = np.round(st)
        off = np.abs(st - rnd).max(axis=1)
        lo, hi = ij.min(axis=0) - 1, ij.max(axis=0) + 1
        inside = (rnd >= lo).all(axis=1) & (rnd <= hi).all(axis=1)
        taken = {tuple(v) for v in nodes.values()}
        best: dict[tuple, tuple] = {}
        for c, node, o in zip(cand[(off < tol) & inside], rnd[(off < tol) & inside], off[(off < tol) & inside]):
            key = (int(node[0]), int(node[1]))
            if key in taken:
                continue
            if key not in best or o < best[key][1]:
                best[key] = (int(c), o)
        if not best:
            break
        for key, (c, _) in best.items():
            nodes[c] = key
    # final check of every member against the homography of all
    ids = np.array(list(nodes))
    ij = np.array([nodes[i] for i in ids], dtype=np.float64)
    H = _homography(ij, uv[ids])
    off = np.abs(_apply_h(np.linalg.inv(H), uv[ids]) - ij).max(axis=1)
    return {int(i): nodes[i] for i, o in zip(ids, off) if o < tol}


def _image_lattices(uv: np.ndarray, min_size: int = 6, max_starts: int = 25) -> list[dict[int, tuple]]:
    """Planar lattices among the detections, largest first."""
    free = np.arange(len(uv))
    groups = []
    while len(free) >= min_size:
        tree = cKDTree(uv[free])
        kq = min(9, len(free))
        dist, nb = tree.query(uv[free], k=kq)
        best: dict[int, tuple] | None = None
        # starts from the most "interior" detections: small, even neighbour distances
        order = np.argsort(dist[:, min(4, kq - 1)] / np.maximum(dist[:, 1], 1e-9))
        for s in order[:max_starts]:
            q = _unit_quad(uv, free, s, nb[s], dist[s])
            if q is None:
                continue
            g = _grow_lattice(uv, free, q)
            if best is None or len(g) > len(best):
                best = g
            if len(best) >= 0.6 * len(free):
                break
        if best is None or len(best) < min_size:
            break
        groups.append(best)
        free = free[~np.isin(free, list(best))]
    return groups


def _unit_quad(uv, free, s, nb, dist):
    p0 = uv[free[s]]
    if len(nb) < 4:
        return None
    n1 = nb[1]
    v1 = uv[free[n1]] - p0
    for n2 in nb[2:]:
        v2 = uv[free[n2]] - p0
        c = v1 @ v2 / (np.linalg.norm(v1) * np.linalg.norm(v2))
        if abs(c) < 0.7:
            break
    else:
        return None
    target = p0 + v1 + v2
    d4 = np.hypot(*(uv[free] - target).T)
    j = int(np.argmin(d4))
    if d4[j] > 0.25 * min(np.linalg.norm(v1), np.linalg.norm(v2)):
        return None
    return [int(free[s]), int(free[n1]), int(free[n2]), int(free[j])]


def _plane_lattice(x: np.ndarray, tol: float = 0.15) -> np.ndarray | None:
    """Integer lattice indices (n, 2) of coplanar points on a regular grid, or None."""
    c = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - c, full_matrices=False)
    p = (x - c) @ vt[:2].T
    if len(p) < 4:
        return None
    dist, nb = cKDTree(p).query(p, k=min(7, len(p)))
    vecs = (p[nb[:, 1:]] - p[:, None, :]).reshape(-1, 2)
    lens = np.hypot(*vecs.T)
    spacing = np.median(dist[:, 1])
    short = vecs[lens < 1.25 * spacing]
    ang = np.mod(np.arctan2(short[:, 1], short[:, 0]), np.pi)
    # dominant direction, then the shortest vectors at > 25 degrees from it
    hist, edges = np.histogram(ang, bins=36, range=(0, np.pi))
    a1 = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    def along(a, vv, la):
        d = np.abs(np.angle(np.exp(1j * (np.mod(np.arctan2(vv[:, 1], vv[:, 0]), np.pi) - a) * 2))) / 2
        return d
    sel1 = along(a1, short, None) < np.radians(8)
    if sel1.sum() == 0:
        return None
    v = short[sel1]
    v = np.where((v @ np.array([np.cos(a1), np.sin(a1)]))[:, None] < 0, -v, v)
    b1 = v.mean(axis=0)
    other = vecs[along(a1, vecs, None) > np.radians(25)]
    if len(other) == 0:
        return None
    lo = np.hypot(*other.T)
    cand = other[lo < 1.15 * lo.min()]
    a2 = np.mod(np.arctan2(cand[:, 1], cand[:, 0]), np.pi)
    a2m = np.median(a2)
    cand = np.where((cand @ np.array([np.cos(a2m), np.sin(a2m)]))[:, None] < 0, -cand, cand)
    b2 = cand.mean(axis=0)
    B = np.column_stack([b1, b2])
    ref = p[np.argmin(np.hypot(*p.T))]
    ij = np.linalg.solve(B, (p - ref).T).T
    rnd = np.round(ij)
    if np.abs(ij - rnd).max() > tol:
        return None
    # least-squares lattice fit and re-check
    A = np.column_stack([np.ones(len(p)), rnd])
    coef, *_ = np.linalg.lstsq(A, p, rcond=None)
    fit = A @ coef
    if np.hypot(*(fit - p).T).max() > tol * spacing:
        return None
    ij = rnd.astype(int)
    if len({tuple(r) for r in ij}) != len(ij):
        return None
    return ij - ij.min(axis=0)


def _unimodular() -> list[np.ndarray]:
    """Integer 2x2 matrices with entries in {-1, 0, 1} and determinant +-1 (lattice symmetries and shears)."""
    mats = []
    for e in itertools.product((-1, 0, 1), repeat=4):
        G = np.array(e).reshape(2, 2)
        if abs(round(np.linalg.det(G))) == 1:
            mats.append(G)
    return mats


_UNIMODULAR = _unimodular()


def _lattice_candidates(S: np.ndarray, W: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(overlap, G, t) with W ≈ G S + t for the lattice maps of (nearly) largest overlap."""
    out = []
    for G in _UNIMODULAR:
        T = S @ G.T
        diff = (W[None, :, :] - T[:, None, :]).reshape(-1, 2)
        keys, counts = np.unique(diff, axis=0, return_counts=True)
        for k in np.flatnonzero(counts == counts.max()):
            out.append((int(counts[k]), G, keys[k]))
    if not out:
        return []
    best = max(c for c, _, _ in out)
    # an undetected marker or two may cost the true map its first place
    return [o for o in out if o[0] >= best - max(1, int(0.05 * best))]


def match_lattice(detected_uv, marker_x, *, max_rms_px: float = 2.0,
                  ambiguity_ratio: float = 4.0) -> tuple[np.ndarray, np.ndarray, CameraModel]:
    """Automatic correspondence for targets with markers on planar grids (open book).

    The markers are split into planes (RANSAC) and each plane's grid is
    indexed; among the detections the planar lattices are grown from unit
    quads with homographies. Every consistent way of mapping the image
    lattices onto the marker grids (lattice symmetries and shifts, which
    wing is which) is scored by the reprojection RMS of its DLT; the best is
    then grown by :func:`propagate`.

    Parameters
    ----------
    detected_uv : array_like (D, 2)
        Detected centres, px.
    marker_x : array_like (M, 3)
        Marker centres, mm.
    max_rms_px : float
        Largest accepted DLT RMS of the best candidate, px.
    ambiguity_ratio : float
        The second-best distinct candidate must have an RMS at least this
        many times larger than the best (and 0.5 px larger).

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel

    Raises
    ------
    CalibrationError
        When no grid is found or the assignment is not certain; the message
        says which seeds to add to the configuration.
    """
    D = np.asarray(detected_uv, dtype=np.float64)
    X = np.asarray(marker_x, dtype=np.float64)
    lattices = _marker_grids(X)
    groups = _image_lattices(D)
    if len(groups) < 2:
        raise CalibrationError(
            f"automatic marker correspondence found {len(groups)} marker grid(s) in the image; it needs two "
            "(both wings). " + SEEDS_HINT
        )
    scored = _scored_maps(_candidate_maps(groups[:3], lattices[:3]), X, D, max_rms_px)
    if not scored:
        raise CalibrationError(
            f"automatic marker correspondence found no assignment of the marker grids that fits a camera "
            f"within {max_rms_px} px RMS. " + SEEDS_HINT
        )
    ranked = _grown(scored, X, D)
    if not ranked:
        raise CalibrationError("automatic marker correspondence could not grow any assignment. " + SEEDS_HINT)
    best = ranked[0]
    if best[1] > max_rms_px:
        raise CalibrationError(
            f"automatic marker correspondence is not sure: the best assignment leaves {best[1]:.2f} px RMS "
            f"(limit {max_rms_px} px). " + SEEDS_HINT
        )
    # when the best assignment explains every detection, an alternative that
    # leaves even one well-formed detection unexplained is decisively worse
    # (that is how an unpainted or coded marker breaks the open book's
    # symmetry); otherwise allow for a few missed or spurious blobs
    slack = 0 if best[0] == len(D) else max(1, int(0.05 * best[0]))
    for n, rms, *_ in ranked[1:]:
        if n >= best[0] - slack and rms < max(ambiguity_ratio * best[1], best[1] + 0.5):
            raise CalibrationError(
                f"automatic marker correspondence is ambiguous: two different assignments fit a camera "
                f"({best[0]} markers at {best[1]:.3f} px RMS and {n} markers at {rms:.3f} px RMS); the target "
                "looks symmetric to the camera. " + SEEDS_HINT
            )
    log.info("automatic correspondence: %d pairs, DLT RMS %.3f px (%d candidates, %d grown)",
             best[0], best[1], len(scored), len(ranked))
    return best[2], best[3], best[4]


def _marker_grids(X: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(members, ij)`` of every marker plane that is a regular grid; CalibrationError when fewer than two."""
    planes = [p for p in find_planes(X) if len(p) >= 6]
    lattices = []
    for members in planes:
        ij = _plane_lattice(X[members])
        if ij is not None:
            lattices.append((members, ij))
    if len(lattices) < 2:
        raise CalibrationError(
            f"automatic marker correspondence needs markers on at least two planar grids; found "
            f"{len(lattices)} (planes: {[len(p) for p in planes]}). " + SEEDS_HINT
        )
    return lattices


def _candidate_maps(groups: list[dict], lattices: list[tuple]) -> dict[tuple[int, int], list[np.ndarray]]:
    """Candidate (marker, detection) pair arrays per (image group, marker plane)."""
    cands = {}
    for gi, g in enumerate(groups):
        det_ids = np.array(list(g))
        S = np.array([g[i] for i in det_ids])
        for li, (members, W) in enumerate(lattices):
            lut = {tuple(w): m for w, m in zip(W.tolist(), members)}
            lst = []
            for count, G, t in _lattice_candidates(S, W):
                T = S @ G.T + t
                pairs = [(lut[tuple(r)], d) for r, d in zip(T.tolist(), det_ids) if tuple(r) in lut]
                lst.append(np.array(pairs))
            cands[gi, li] = lst
    return cands


def _scored_maps(cands: dict, X: np.ndarray, D: np.ndarray, max_rms_px: float) -> list[tuple]:
    """``(rms, pairs, model)`` of every two-wing combination whose DLT fits within ``max_rms_px``."""
    scored = []
    for (ga, la), (gb, lb) in itertools.permutations(cands, 2):
        if ga >= gb or la == lb:
            continue
        for pa in cands[ga, la]:
            for pb in cands[gb, lb]:
                pairs = np.vstack([pa, pb])
                try:
                    model = CameraModel(dlt(X[pairs[:, 0]], D[pairs[:, 1]]))
                except CalibrationError:
                    continue
                rms = reprojection_rms(model, X[pairs[:, 0]], D[pairs[:, 1]])
                if rms <= max_rms_px:
                    scored.append((rms, pairs, model))
    return scored


def _grown(scored: list[tuple], X: np.ndarray, D: np.ndarray) -> list[tuple]:
    """Distinct propagated assignments ``(n, rms, mi, di, model)``, most pairs first, then smallest RMS.

    Every acceptable candidate is grown over all markers and detections;
    the true one explains the most detections (a shifted or rotated grid
    leaves a row or column unmatched), with the smallest RMS.
    """
    grown = {}
    for rms, pairs, model in sorted(scored, key=lambda s: s[0])[:20]:
        try:
            mi, di, m = propagate(model, X, D)
        except CalibrationError:
            continue
        key = (tuple(mi), tuple(di))
        if key not in grown:
            grown[key] = (len(mi), reprojection_rms(m, X[mi], D[di]), mi, di, m)
    return sorted(grown.values(), key=lambda g: (-g[0], g[1]))
