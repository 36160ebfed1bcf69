"""In-plane strain of a curved surface from its tangent vectors (after Hartmann et al. 2021).

With the tangents ``A_alpha`` (reference) and ``a_alpha`` (current) of the same
surface parameters ``Psi``, the in-plane deformation gradient is
``F = a_alpha (x) A^alpha`` (``A^alpha`` the reference dual vectors), and the
Green-Lagrange strain on the reference tangent plane

    E = (F^T F - P_0) / 2 = (a_ab - A_ab) / 2  A^a (x) A^b,

``P_0 = A_alpha (x) A^alpha`` the reference tangent projector. ``E`` is given
as a 3 x 3 tensor in the DIC frame (zero along the reference normal) and as
2 x 2 components in the orthonormal reference tangent basis ``E_1 = A_1 /
|A_1|``, ``E_2 = N x E_1`` (``N`` the reference unit normal).

All functions are vectorised over any leading shape (time, point, ...);
NaN in gives NaN out.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from .errors import ConfigError
from .numerics.threads import parallel_map, worker_slices
from .validation import shaped_array

__all__ = [
    "Strain",
    "deformation_gradient",
    "reference_basis",
    "strain",
    "strain_tensor",
    "strain_components",
    "principal_2d",
    "equivalent_strain",
]

log = logging.getLogger(__name__)

# Principal directions are undefined where the two principal values are equal;
# NaN below this difference.
DIRECTION_TOL = 1e-8


def _dot(x, y):
    """Dot product over the last axis (einsum on equal shapes: 4x faster than sum(x * y, -1))."""
    x, y = np.broadcast_arrays(x, y)
    return np.einsum("...i,...i->...", x, y)


def _dual(a):
    """Dual vectors ``a^alpha`` (..., 2, 3) and metric (..., 2, 2); NaN where singular."""
    g = np.einsum("...ai,...bi->...ab", a, a)
    det = g[..., 0, 0] * g[..., 1, 1] - g[..., 0, 1] ** 2
    inv = np.stack(
        [np.stack([g[..., 1, 1], -g[..., 0, 1]], -1), np.stack([-g[..., 0, 1], g[..., 0, 0]], -1)], -2
    ) / det[..., None, None]
    # |a1 x a2|^2 = det: a zero (or tiny) area is a singular metric
    scale = g[..., 0, 0] * g[..., 1, 1]
    bad = ~(det > 1e-12 * scale)
    inv[bad] = np.nan
    return np.einsum("...ab,...bi->...ai", inv, a), g


def deformation_gradient(tangents, ref_tangents):
    """In-plane deformation gradient ``F = a_alpha (x) A^alpha``.

    Parameters
    ----------
    tangents : array_like, shape (..., 2, 3)
        Current tangents ``a_alpha``.
    ref_tangents : array_like, shape (..., 2, 3)
        Reference tangents ``A_alpha`` (broadcast against ``tangents``, e.g.
        (N, 2, 3) against (T, N, 2, 3)).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``F`` (dimensionless); ``F A_alpha = a_alpha``, ``F N = 0``.
    """
    a = shaped_array(tangents, "tangents", (2, 3))
    A = shaped_array(ref_tangents, "ref_tangents", (2, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        Ad, _ = _dual(A)
        return np.einsum("...ai,...aj->...ij", a, Ad)


def reference_basis(ref_tangents):
    """Orthonormal reference tangent basis ``E_1 = A_1/|A_1|``, ``E_2 = N x E_1`` and normal ``N``.

    Parameters
    ----------
    ref_tangents : array_like, shape (..., 2, 3)

    Returns
    -------
    basis : ndarray, shape (..., 2, 3)
        Rows ``E_1``, ``E_2``.
    normal : ndarray, shape (..., 3)
        ``N = A_1 x A_2 / |A_1 x A_2|``.
    """
    A = shaped_array(ref_tangents, "ref_tangents", (2, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.cross(A[..., 0, :], A[..., 1, :])
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        e1 = A[..., 0, :] / np.linalg.norm(A[..., 0, :], axis=-1, keepdims=True)
        e2 = np.cross(n, e1)
    return np.stack([e1, e2], axis=-2), n


def principal_2d(E2):
    """Principal values and angle of symmetric 2 x 2 tensors.

    Parameters
    ----------
    E2 : array_like, shape (..., 2, 2)

    Returns
    -------
    e_max, e_min : ndarray, shape (...)
    angle : ndarray, shape (...)
        Angle (rad) of the direction of ``e_max`` from the first basis vector,
        in (-pi/2, pi/2]; NaN where ``e_max - e_min <= 1e-8``.
    """
    E2 = np.asarray(E2, dtype=float)
    with np.errstate(invalid="ignore"):
        m = 0.5 * (E2[..., 0, 0] + E2[..., 1, 1])
        d = 0.5 * (E2[..., 0, 0] - E2[..., 1, 1])
        o = 0.5 * (E2[..., 0, 1] + E2[..., 1, 0])
        r = np.hypot(d, o)
        ang = 0.5 * np.arctan2(2 * o, 2 * d)
        ang = np.where(r > 0.5 * DIRECTION_TOL, ang, np.nan)
    return m + r, m - r, ang


def equivalent_strain(e_max, e_min):
    """Von Mises-type equivalent strain of a plane state with volume constancy.

    ``eps_eq = (2 / sqrt(3)) sqrt(e1^2 + e1 e2 + e2^2)``, i.e.
    ``sqrt(2/3 (e1^2 + e2^2 + e3^2))`` with the thickness strain ``e3 = -e1 - e2``
    (the ARAMIS "von Mises strain" when fed logarithmic principal strains).

    Parameters
    ----------
    e_max, e_min : array_like
        In-plane principal strains (any measure; :func:`strain` uses the
        logarithmic ones, ``ln(lambda_i)``).

    Returns
    -------
    ndarray
    """
    e1 = np.asarray(e_max, dtype=float)
    e2 = np.asarray(e_min, dtype=float)
    with np.errstate(invalid="ignore"):
        return (2.0 / np.sqrt(3.0)) * np.sqrt(e1 * e1 + e1 * e2 + e2 * e2)


def strain_tensor(E2, basis):
    """3 x 3 tensor ``E = E2_ij E_i (x) E_j`` from components in an orthonormal tangent basis.

    Parameters
    ----------
    E2 : array_like, shape (..., 2, 2)
    basis : array_like, shape (..., 2, 3)
        Rows ``E_1``, ``E_2`` (broadcast against ``E2``).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    E2 = np.asarray(E2, dtype=float)
    B = np.asarray(basis, dtype=float)
    B1, B2 = B[..., 0, :], B[..., 1, :]
    M12 = B1[..., :, None] * B2[..., None, :]
    return (E2[..., 0, 0, None, None] * (B1[..., :, None] * B1[..., None, :])
            + E2[..., 0, 1, None, None] * (M12 + np.swapaxes(M12, -1, -2))
            + E2[..., 1, 1, None, None] * (B2[..., :, None] * B2[..., None, :]))


class Strain(NamedTuple):
    """Result of :func:`strain`; ``...`` is the leading shape (e.g. time, point)."""

    F: np.ndarray
    """(..., 3, 3) in-plane deformation gradient ``a_alpha (x) A^alpha`` (None unless ``tensors``)."""
    E: np.ndarray
    """(..., 3, 3) Green-Lagrange strain in the DIC frame, on the reference tangent plane (None unless ``tensors``)."""
    E2: np.ndarray
    """(..., 2, 2) components of E in the reference basis ``(E_1, E_2)``."""
    basis: np.ndarray
    """(..., 2, 3) the reference basis ``E_1 = A_1/|A_1|``, ``E_2 = N x E_1`` (shape of ``ref_tangents``)."""
    e_max: np.ndarray
    """(...) maximum in-plane principal Green-Lagrange strain."""
    e_min: np.ndarray
    """(...) minimum in-plane principal Green-Lagrange strain."""
    direction_max: np.ndarray
    """(..., 3) unit direction of e_max, reference configuration (NaN where e_max = e_min)."""
    direction_min: np.ndarray
    """(..., 3) unit direction of e_min, reference configuration."""
    direction_max_current: np.ndarray
    """(..., 3) ``F N_max / |F N_max|``, current configuration."""
    direction_min_current: np.ndarray
    """(..., 3) ``F N_min / |F N_min|``."""
    stretch_max: np.ndarray
    """(...) principal stretch ``sqrt(1 + 2 e_max)``."""
    stretch_min: np.ndarray
    """(...) principal stretch ``sqrt(1 + 2 e_min)``."""
    equivalent: np.ndarray
    """(...) :func:`equivalent_strain` of the logarithmic strains ``ln(stretch)``."""


def strain(tangents, ref_tangents, *, tensors=True):
    """In-plane Green-Lagrange strain, principal values and directions.

    Parameters
    ----------
    tangents : array_like, shape (..., 2, 3)
        Current tangents ``a_alpha``.
    ref_tangents : array_like, shape (..., 2, 3)
        Reference tangents ``A_alpha``, broadcast against ``tangents`` (e.g.
        (N, 2, 3) against (T, N, 2, 3)).
    tensors : bool
        Also return the 3 x 3 ``F`` and ``E`` (else None there; ``E`` follows
        from ``E2`` and ``basis`` by :func:`strain_tensor`). At 500 stages x
        10,000 points they are 355 MB each and take most of the time.

    Returns
    -------
    Strain
        ``basis`` has the leading shape of ``ref_tangents``; all other fields
        the broadcast leading shape. Principal directions are signed so that
        their component along ``E_2`` is positive (along ``E_1`` when
        perpendicular to ``E_2``).

    Notes
    -----
    With ``Q_ia = E_i . A^a`` the 2 x 2 components are
    ``E2 = Q (a_ab - A_ab) Q^T / 2`` and the 3 x 3 tensor is
    ``E = E2_ij E_i (x) E_j``. Written out component by component (no
    ``einsum`` over the large arrays): 500 stages x 10,000 points take ~2 s.
    """
    a = shaped_array(tangents, "tangents", (2, 3))
    A = shaped_array(ref_tangents, "ref_tangents", (2, 3))
    try:
        shape = np.broadcast_shapes(a.shape, A.shape)
    except ValueError:
        raise ConfigError(f"tangents {a.shape} and ref_tangents {A.shape} do not broadcast") from None
    lead = shape[:-2]
    if tensors or a.shape != shape or A.ndim >= a.ndim or not lead[0]:
        return _strain(a, A, lead, tensors)
    # pointwise: blocks of the first axis (times) on the stage's threads give the same numbers
    trail = dict(E2=(2, 2), direction_max=(3,), direction_min=(3,), direction_max_current=(3,),
                 direction_min_current=(3,))
    out = {k: np.empty(lead + trail.get(k, ())) for k in Strain._fields if k not in ("F", "E", "basis")}

    def block(sl):
        part = _strain(a[sl], A, (a[sl].shape[0],) + lead[1:], False)
        for k, v in out.items():
            v[sl] = getattr(part, k)
        return part.basis

    basis = parallel_map(block, worker_slices(lead[0]))[0]
    return Strain(F=None, E=None, basis=basis, **out)


def _strain(a, A, lead, tensors):
    """:func:`strain` of the arrays ``a`` and ``A`` of broadcast leading shape ``lead``."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        E2, basis, Ad = _components(a, A, lead)
        B1, B2 = basis[..., 0, :], basis[..., 1, :]
        a1, a2 = a[..., 0, :], a[..., 1, :]
        E = F = None
        if tensors:
            E = strain_tensor(E2, basis)
            F = a1[..., :, None] * Ad[..., 0, None, :] + a2[..., :, None] * Ad[..., 1, None, :]
            F = np.ascontiguousarray(np.broadcast_to(F, lead + (3, 3)))
        e_max, e_min, ang = principal_2d(E2)
        c, s = np.cos(ang)[..., None], np.sin(ang)[..., None]
        d_max = _sign(c * B1 + s * B2, B1, B2)
        d_min = _sign(c * B2 - s * B1, B1, B2)
        cur = []
        for d in (d_max, d_min):
            # F d = a_alpha (A^alpha . d)
            v = a1 * _dot(Ad[..., 0, :], d)[..., None] + a2 * _dot(Ad[..., 1, :], d)[..., None]
            cur.append(v / np.sqrt(_dot(v, v))[..., None])
        l_max = np.sqrt(1 + 2 * e_max)
        l_min = np.sqrt(1 + 2 * e_min)
        eq = equivalent_strain(np.log(l_max), np.log(l_min))
    return Strain(F, E, E2, basis, e_max, e_min, d_max, d_min, cur[0], cur[1], l_max, l_min, eq)


def strain_components(tangents, ref_tangents):
    """The 2 x 2 Green-Lagrange strain ``E2`` (..., 2, 2) of :func:`strain` alone (no principal values or
    directions: the uncertainty probes need only the tensor, at about a fifth of the cost)."""
    a = shaped_array(tangents, "tangents", (2, 3))
    A = shaped_array(ref_tangents, "ref_tangents", (2, 3))
    try:
        lead = np.broadcast_shapes(a.shape, A.shape)[:-2]
    except ValueError:
        raise ConfigError(f"tangents {a.shape} and ref_tangents {A.shape} do not broadcast") from None
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return _components(a, A, lead)[0]


def _components(a, A, lead):
    """``E2`` (lead + (2, 2)), the reference basis and dual vectors (:func:`strain`, Notes)."""
    Ad, G = _dual(A)
    basis, _ = reference_basis(A)
    Q = np.einsum("...ik,...ak->...ia", basis, Ad)  # reference-sized: cheap
    a1, a2 = a[..., 0, :], a[..., 1, :]
    D11 = _dot(a1, a1) - G[..., 0, 0]
    D12 = _dot(a1, a2) - G[..., 0, 1]
    D22 = _dot(a2, a2) - G[..., 1, 1]
    q11, q12, q21, q22 = Q[..., 0, 0], Q[..., 0, 1], Q[..., 1, 0], Q[..., 1, 1]
    E11 = 0.5 * (q11 * q11 * D11 + 2 * q11 * q12 * D12 + q12 * q12 * D22)
    E22 = 0.5 * (q21 * q21 * D11 + 2 * q21 * q22 * D12 + q22 * q22 * D22)
    E12 = 0.5 * (q11 * q21 * D11 + (q11 * q22 + q12 * q21) * D12 + q12 * q22 * D22)
    E11, E12, E22 = (np.broadcast_to(v, lead) for v in (E11, E12, E22))
    return np.stack([np.stack([E11, E12], -1), np.stack([E12, E22], -1)], -2), basis, Ad


def _sign(d, B1, B2):
    """Flip ``d`` so that ``d . E_2 > 0`` (``d . E_1 > 0`` when ``d . E_2 ~ 0``)."""
    s2 = _dot(d, B2)
    s1 = _dot(d, B1)
    sign = np.where(np.abs(s2) > 1e-12, np.sign(s2), np.sign(s1))
    sign = np.where(sign == 0, 1.0, sign)
    return d * sign[..., None]
