"""User-given seeds: the pixel positions of a few markers, checked against each other and the final camera.

:func:`match_seeds` snaps the seeds to their detections, judges them by a
robust camera of all of them (RANSAC over minimal sets,
:func:`_robust_seed_fit`) and grows the correspondence from it
(:func:`irdic.calibration.correspondence.grow_from_seeds`);
:func:`match_seeds_deferred` with :func:`judge_pending` judges the seeds that
the camera of the others misses again by the camera of every matched marker,
and :func:`warn_seeds_off` names seeds that the calibrated camera puts
off their markers.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import warnings
from typing import Mapping

import numpy as np

from ..camera import CameraModel, dlt, planarity
from ..camera.dlt import degeneracy
from scipy.spatial import cKDTree

from ..errors import CalibrationError, ConfigError, IrdicWarning
from .correspondence import SEEDS_HINT, grow_from_seeds

__all__ = ["match_seeds", "match_seeds_deferred", "judge_pending", "PendingSeeds", "warn_seeds_off",
           "SEEDS_HINT", "SEED_TOLERANCE_PX"]

log = logging.getLogger(__name__)

#: Default largest distance (px) of a clicked seed from the camera fitted to the seeds.
SEED_TOLERANCE_PX = 6.0


def _seed_table(seeds: Mapping, marker_ids) -> tuple[np.ndarray, np.ndarray, list]:
    if not isinstance(seeds, Mapping):
        raise ConfigError(f"`seeds` must be a mapping {{marker_id: [u, v]}}, got {type(seeds).__name__}")
    lookup = {str(m): i for i, m in enumerate(np.asarray(marker_ids).tolist())}
    unknown = [k for k in seeds if str(k) not in lookup]
    if unknown:
        raise ConfigError(
            f"seeds name marker IDs that are not in the marker file: {sorted(map(str, unknown))}; "
            f"known IDs are e.g. {list(lookup)[:8]}"
        )
    idx, uv, keys = [], [], []
    for k, val in seeds.items():
        try:
            pos = np.asarray(val, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            pos = np.zeros(0)
        if pos.shape != (2,) or not np.isfinite(pos).all():
            raise ConfigError(f"seeds[{k!r}] must be a pair [u, v] of pixel positions, got {val!r}")
        idx.append(lookup[str(k)])
        uv.append(pos)
        keys.append(k)
    if len(set(idx)) != len(idx):
        raise ConfigError("seeds name the same marker twice (keys that differ only in type, e.g. 12 and '12')")
    if len(idx) < 6:
        raise ConfigError(f"`seeds` needs at least 6 markers (11 camera parameters), got {len(idx)}")
    return np.array(idx), np.array(uv), keys


def match_seeds(detected_uv, marker_x, marker_ids, seeds: Mapping, *, gate_px: float | None = None,
                seed_tolerance_px: float | None = None) -> tuple[np.ndarray, np.ndarray, CameraModel]:
    """Correspondence from a few user-given marker positions.

    Each seed is snapped to the nearest detection where that is unambiguous;
    the seeds are judged against a camera fitted robustly to all of them
    (RANSAC over 6-seed DLTs, :func:`_robust_seed_fit`): every seed must lie
    within ``seed_tolerance_px`` of it, else the ones that do not are named.
    The DLT through the seeds predicts all markers, and :func:`propagate`
    grows the assignment. :func:`match_seeds_deferred` judges the seeds that
    the camera of the others misses again, by the camera of all markers
    matched later.

    Parameters
    ----------
    detected_uv : array_like (D, 2)
        Detected centres, px.
    marker_x : array_like (M, 3)
        Marker centres, mm.
    marker_ids : array_like (M,)
        Marker IDs (compared as strings with the seed keys).
    seeds : mapping
        ``{marker_id: (u, v)}`` for at least 6 markers, a few px off at most.
    gate_px : float, optional
        Assignment gate (default per marker: 0.4 x the distance of its
        predicted position from the nearest other predicted marker).
    seed_tolerance_px : float, optional
        Largest accepted distance of a seed from the camera fitted robustly
        to all seeds (default :data:`SEED_TOLERANCE_PX` = 6 px: honest
        clicks are a few px off, a seed on a neighbouring marker a marker
        spacing).

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel

    Raises
    ------
    ConfigError
        Unknown seed IDs, fewer than 6 seeds, coplanar seeds or seeds that
        contradict each other (the worst one is named).
    """
    D = np.asarray(detected_uv, dtype=np.float64)
    X = np.asarray(marker_x, dtype=np.float64)
    seen = _judge_seeds(D, X, marker_ids, seeds, seed_tolerance_px)
    if seen.pending.any():
        raise ConfigError(_seed_message(seen.keys, seen.uv, ~seen.pending, seen.model, seen.residual_px,
                                        seen.tolerance_px))
    return grow_from_seeds(seen.model, X, D, seen.index[~seen.pending], gate_px=gate_px)


@dataclasses.dataclass(frozen=True)
class PendingSeeds:
    """Seeds judged by the camera of the others; those it misses are judged again by that of all matched markers.

    Attributes
    ----------
    keys : list
        Seed keys (marker IDs as given), all seeds.
    index : ndarray of int (n,)
        Index of each seed's marker into ``marker_x``.
    uv : ndarray (n, 2)
        Seed positions, px (snapped to their detection where that was unambiguous).
    pending : ndarray of bool (n,)
        The seeds farther than the tolerance from the camera of the others.
    residual_px : ndarray (n,)
        Distance of every seed from that camera, px.
    tolerance_px : float
        Seed tolerance, px.
    model : CameraModel
        DLT of the seeds within the tolerance.
    """

    keys: list
    index: np.ndarray
    uv: np.ndarray
    pending: np.ndarray
    residual_px: np.ndarray
    tolerance_px: float
    model: CameraModel


def match_seeds_deferred(detected_uv, marker_x, marker_ids, seeds: Mapping, *, gate_px: float | None = None,
                         seed_tolerance_px: float | None = None):
    """:func:`match_seeds`, but seeds missed only by the camera of the others are judged later.

    Parameters and errors as :func:`match_seeds`, except that when at least
    6 seeds agree on a camera the others are not refused here: the
    correspondence grows from the camera of the agreeing ones, and
    :func:`judge_pending` judges the rest by the camera of every marker
    matched in the end.

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel
    pending : PendingSeeds or None
        None when every seed lies within the tolerance.

    Notes
    -----
    The camera of 6-8 seeds extrapolates poorly where the seeds lie close
    together: on a wing seen 74 deg from its normal, with its faint markers
    not yet detected (so their seeds are judged as clicked), the camera of
    seven seeds put an honest click 2.9 px from its marker 6.6 px off
    (calibration benchmark, noise field 19, contrast/noise 3, 4 K gradient);
    the camera of the 84 markers matched from those seven puts it 2.9 px
    off. A seed on the wrong marker stays about a marker spacing off.
    """
    D = np.asarray(detected_uv, dtype=np.float64)
    X = np.asarray(marker_x, dtype=np.float64)
    seen = _judge_seeds(D, X, marker_ids, seeds, seed_tolerance_px)
    return (*grow_from_seeds(seen.model, X, D, seen.index[~seen.pending], gate_px=gate_px),
            seen if seen.pending.any() else None)


def _judge_seeds(D: np.ndarray, X: np.ndarray, marker_ids, seeds: Mapping, seed_tolerance_px) -> PendingSeeds:
    """The seeds snapped and judged by the robust camera of all of them (ConfigError when no 6 agree)."""
    idx, suv, keys = _seed_table(seeds, marker_ids)
    tol = float(seed_tolerance_px) if seed_tolerance_px is not None else SEED_TOLERANCE_PX
    if not (np.isfinite(tol) and tol > 0):
        raise ConfigError(f"`seed_tolerance_px` must be a positive number of pixels, got {seed_tolerance_px!r}")
    clicked = suv
    suv, snap = _snap_seeds(D, suv, keys)
    _check_seed_layout(X[idx])
    inl, model, res = _robust_seed_fit(X[idx], suv, tol)
    if model is not None and (snap & ~inl).any():
        # where its marker was not detected, a click may have snapped to a neighbour: the click
        # itself is what the user said
        suv = np.where((snap & ~inl)[:, None], clicked, suv)
        inl, model, res = _robust_seed_fit(X[idx], suv, tol)
    if model is None:
        raise ConfigError(_seed_message(keys, suv, inl, model, res, tol))
    return PendingSeeds(keys, idx, suv, ~inl, res, tol, model)


def judge_pending(pending: PendingSeeds | None, marker_x, detected_uv, marker_index, detection_index) -> None:
    """Refuse the pending seeds that the camera of all matched markers also puts off their markers.

    Parameters
    ----------
    pending : PendingSeeds or None
        From :func:`match_seeds_deferred` (None: nothing to judge).
    marker_x : array_like (M, 3)
        Marker centres, mm.
    detected_uv : array_like (D, 2)
        Detected centres, px.
    marker_index, detection_index : array_like of int
        The matched pairs; their DLT is the judge (the camera of the agreeing
        seeds where it cannot be fitted, e.g. every matched marker on one wing).

    Raises
    ------
    ConfigError
        A pending seed lies farther than the seed tolerance from the
        projection of its marker by that camera (the seeds are named, with
        their distance and the tolerance in px).
    """
    if pending is None:
        return
    X = np.asarray(marker_x, dtype=np.float64)
    mi, di = np.asarray(marker_index, dtype=int), np.asarray(detection_index, dtype=int)
    try:
        model = CameraModel(dlt(X[mi], np.asarray(detected_uv, dtype=np.float64)[di]))
        judge = f"the camera of the {len(mi)} markers matched with the other seeds"
    except CalibrationError:
        model, judge = pending.model, "the camera of the other seeds"
    res = np.hypot(*(model.project(X[pending.index]) - pending.uv).T)
    res = np.where(np.isfinite(res), res, np.inf)
    bad = pending.pending & (res > pending.tolerance_px)
    if bad.any():
        msg = _seed_message(pending.keys, pending.uv, ~bad, model, res, pending.tolerance_px, judge)
        if len(mi) < 0.5 * len(X):
            # a seed on a neighbouring marker among the others can hold their growth to a few markers, and
            # their camera then blames an honest seed (seeds close together on a steep wing)
            msg += (f". The other seeds matched only {len(mi)} of the {len(X)} markers, so one of them may be "
                    "the wrong one instead")
        raise ConfigError(msg)
    for p in np.flatnonzero(pending.pending):
        log.info("seed %r is %.1f px from its marker by %s (tolerance %.1f px), %.1f px by the camera of the "
                 "other seeds", pending.keys[p], res[p], judge, pending.tolerance_px, pending.residual_px[p])


def _spacing(uv: np.ndarray) -> float:
    """Median nearest-neighbour distance of the detections, px."""
    if len(uv) < 2:
        return np.inf
    d, _ = cKDTree(uv).query(uv, k=2)
    return float(np.median(d[:, 1]))


def _snap_seeds(D: np.ndarray, suv: np.ndarray, keys: list) -> tuple[np.ndarray, np.ndarray]:
    """Seed positions (n, 2) px snapped to a detection where that is unambiguous, and which were snapped.

    Raises
    ------
    ConfigError
        A seed lies several marker spacings from every detection.
    """
    snap = np.zeros(len(suv), bool)
    if len(D) < 2:
        return suv, snap
    spacing = _spacing(D)
    d, j = cKDTree(D).query(suv, k=2)
    # a seed several marker spacings away from every blob points at no
    # marker at all (off the target, u and v swapped, a typo): say so
    # rather than letting the fit report the seeds as degenerate. (One
    # spacing is not enough: the neighbours of an undetected marker on a
    # faint or foreshortened wing may be undetected too.)
    far = np.flatnonzero(d[:, 0] > max(3.0 * spacing, 3.0))
    if far.size:
        names = "; ".join(f"seed for marker {keys[f]!r} at ({suv[f, 0]:.1f}, {suv[f, 1]:.1f}) is "
                          f"{d[f, 0]:.1f} px from any detected blob" for f in far[:5])
        raise ConfigError(
            f"{names} (detections are {spacing:.1f} px apart); give the pixel position (u = column, v = row) "
            "of a detected marker, read off the detection figure"
        )
    # snap a click to a detection only where that is unambiguous (the next detection is 3x
    # farther): on a strongly foreshortened wing the neighbours are closer than a click's error
    snap = (d[:, 0] <= 0.5 * spacing) & (d[:, 1] > 3.0 * d[:, 0])
    return np.where(snap[:, None], D[j[:, 0]], suv), snap


def _check_seed_layout(x: np.ndarray) -> None:
    """ConfigError when the seed markers ``x`` (n, 3) mm are collinear or coplanar."""
    line = degeneracy(x, "seed markers")
    if line is not None and "coplanar" not in line:
        raise ConfigError(f"{line}, so they do not determine a camera; choose seeds spread over both wings of "
                          "the target")
    thick = planarity(x)
    if thick < 1e-3:
        raise ConfigError(
            f"the {len(x)} seed markers are coplanar (thickness ratio {thick:.1e}), so they do not determine a "
            "camera; choose seeds spread over both wings of the target"
        )


def _robust_seed_fit(x: np.ndarray, uv: np.ndarray, tol: float, max_sets: int = 400, seed: int = 0):
    """Seeds that agree on one camera: RANSAC over minimal (6-point) DLT sets.

    Every 6-seed subset (or ``max_sets`` random ones when there are more),
    and with 8 or more seeds every set without one seed and the full set,
    gives a DLT; the one that puts the most seeds within ``tol`` px (ties:
    smallest sum of squared residuals capped at ``tol``) wins, and the DLT
    of its inliers is refitted until the inlier set is stable.

    Returns
    -------
    inliers : ndarray of bool (n,)
    model : CameraModel or None
        DLT of the inliers (None when no subset gives a camera).
    residuals : ndarray (n,)
        Distance of every seed from the projection of its marker by ``model``, px.

    Notes
    -----
    Leave-one-out DLTs through the other seeds do not work here: with 7 or 8
    seeds on an oblique view the system is so ill-conditioned that an
    honest 2 px click error is magnified to tens of px. A minimal set that
    avoids a wrong seed predicts the honest ones within a few px, and the
    wrong one by about a marker spacing.
    """
    n = len(x)
    combos = itertools.combinations(range(n), 6)
    n_sets = int(np.prod(np.arange(n - 5, n + 1)) // 720)
    if n_sets > max_sets:
        rng = np.random.default_rng(seed)
        combos = (np.sort(rng.choice(n, 6, replace=False)) for _ in range(max_sets))
    # the sets without one seed and the full set as well: a 6-point DLT through clicks a few px
    # off can extrapolate poorly on an oblique view, where all honest seeds together fit well
    larger = [[j for j in range(n) if j != i] for i in range(n)] + [list(range(n))] if n >= 8 else []
    best, best_key, best_fit = None, (-1, -np.inf), None
    fatal = None
    for sub in itertools.chain(combos, larger):
        sub = list(sub)
        if planarity(x[sub]) < 1e-3:
            continue
        try:
            cam = CameraModel(dlt(x[sub], uv[sub]))
            res = np.hypot(*(cam.project(x) - uv).T)
        except CalibrationError as exc:
            # inconsistent seeds put some markers behind the camera; a mirrored
            # image puts all of them there, which no choice of seeds mends
            if getattr(exc, "reason", None) != "inconsistent":
                fatal = fatal or exc
            continue
        res = np.where(np.isfinite(res), res, np.inf)
        inl = res <= tol
        key = (int(inl.sum()), -float(np.minimum(res, tol) ** 2 @ np.ones(n)))
        if key > best_key:
            best, best_key, best_fit = inl, key, (cam, res)
    if best is None and fatal is not None:
        raise fatal
    if best is None or best.sum() < 6:
        return np.zeros(n, bool) if best is None else best, None, np.full(n, np.inf)
    inl = best
    model, res = best_fit
    for _ in range(5):
        try:
            refit = CameraModel(dlt(x[inl], uv[inl]))
        except CalibrationError:
            # the DLT of all the inliers can be worse conditioned than the set that found them (an
            # oblique wing's seeds close together: mirrored by 4 px of one click); keep the last camera
            break
        model, res = refit, np.hypot(*(refit.project(x) - uv).T)
        new = res <= tol
        if new.sum() < 6 or (new == inl).all():
            break
        inl = new
    return inl, model, res


def _seed_message(keys, suv, inl, model, res, tol, judged_by: str = "the camera of the other seeds") -> str:
    """User message for seeds that do not agree on one camera (culprits named by marker ID, ``judged_by``)."""
    n = len(keys)
    if model is None:
        return (f"the seeds contradict each other: no 6 of the {n} seeds fit one camera within {tol:.1f} px "
                "(the seed tolerance); check their marker IDs and positions (u = column, v = row)")
    bad = np.flatnonzero(~inl)
    names = " and ".join(f"seed {keys[b]!r} at {suv[b].round(1).tolist()} ({res[b]:.1f} px off)" for b in bad)
    return (f"the seeds contradict each other: {n - len(bad)} of the {n} seeds fit one camera within "
            f"{tol:.1f} px (the seed tolerance), {len(bad)} do not; the worst "
            f"{'is' if len(bad) == 1 else 'are'} {names}, judged by {judged_by}. A seed "
            "that far off is probably on another marker: check its marker ID and position")


def warn_seeds_off(model: CameraModel, marker_x, marker_ids, seeds: Mapping | None, rms_px: float,
                   tolerance_px: float = SEED_TOLERANCE_PX) -> list[str]:
    """Warn of the seeds that the calibrated camera puts farther than ``tolerance_px`` from their markers.

    Parameters
    ----------
    model : CameraModel
        The calibrated camera.
    marker_x : array_like (M, 3)
        Marker centres, mm.
    marker_ids : array_like (M,)
        Their IDs.
    seeds : mapping or None
        ``{marker_id: [u, v]}`` as given (px); None or empty: nothing to check.
    rms_px : float
        The calibration's RMS residual, px (for the message).
    tolerance_px : float
        Largest distance of an honest click from its marker's projection, px.

    Returns
    -------
    list of str
        One phrase per such seed (ID, position, distance), worst first, as warned
        (:class:`~irdic.errors.IrdicWarning`); empty when there is none.

    Notes
    -----
    The seed check before the fit judges seeds by cameras of a few points,
    which extrapolate poorly where the seeds lie close together: a seed on
    the neighbour of its marker may pass it (on a wing seen 74 deg from its
    normal, markers ~10 px apart) when the correspondence and the fit of all
    markers do not depend on it. The calibrated camera rests on every
    matched marker, so a seed it puts more than the tolerance off its
    marker was not clicked on that marker.
    """
    if not seeds:
        return []
    idx, suv, keys = _seed_table(seeds, marker_ids)
    res = np.hypot(*(model.project(np.asarray(marker_x, dtype=np.float64)[idx]) - suv).T)
    res = np.where(np.isfinite(res), res, np.inf)
    off = np.flatnonzero(res > tolerance_px)
    out = [f"seed {keys[i]!r} at ({suv[i, 0]:.1f}, {suv[i, 1]:.1f}) is {res[i]:.1f} px from the projection of its "
           f"marker" for i in off[np.argsort(-res[off])]]
    if out:
        warnings.warn(f"calibration: {'; '.join(out)} by the calibrated camera (RMS {rms_px:.2f} px over the "
                      f"markers), more than the seed tolerance of {tolerance_px:g} px: probably clicked on another "
                      "marker (the calibration does not rest on it); correct it in the configuration", IrdicWarning,
                      stacklevel=3)  # the caller of calibrate
    return out
