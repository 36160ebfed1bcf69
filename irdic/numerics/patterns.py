"""Grouping by missing-data pattern: the rows of a boolean mask that are identical.

Fills of missing values solve one small system per pattern; stages (or
series) sharing a pattern, as noise probes repeat the data's, share it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["same_patterns"]


def same_patterns(mask) -> list[np.ndarray]:
    """Row indices of ``mask`` grouped by identical rows.

    Parameters
    ----------
    mask : array_like of bool, shape (M, N)

    Returns
    -------
    list of ndarray of int
        One array per distinct row, in the order of the distinct rows'
        packed bytes; within a group the rows in increasing order. Empty for
        M = 0.
    """
    m = np.asarray(mask, dtype=bool)
    if m.shape[0] == 0:
        return []
    _, group = np.unique(np.packbits(m, axis=1), axis=0, return_inverse=True)
    group = np.ravel(group)
    order = np.argsort(group, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(group[order])) + 1)
