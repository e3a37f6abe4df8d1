"""Inverses of 3 x 3 and affine 4 x 4 matrices in closed form.

Not ``numpy.linalg.inv``: numpy's OpenBLAS solves even a 3 x 3 system on
its worker threads, which then spin for about 0.1 s and take a core from
the kernels the render launches next (on two cores F12's photon tracing
ran up to twice as long; README, "numpy's BLAS threads and the first kernels").
"""

from __future__ import annotations

import numpy as np


def cofactors(m: np.ndarray) -> tuple[np.ndarray, float]:
    """The cofactor matrix of 3 x 3 ``m`` (the transpose of its inverse
    times its determinant: each row the cross product of the other two
    rows of ``m``) and the determinant."""
    r0, r1, r2 = (np.asarray(m[i], np.float64) for i in range(3))
    cof = np.array([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)])
    return cof, float(np.sum(r0 * cof[0]))


def affine_inverse(m) -> np.ndarray:
    """The inverse of affine 4 x 4 ``m`` (last row 0, 0, 0, 1), float64;
    numpy's LinAlgError when it is singular."""
    m = np.asarray(m, np.float64)
    cof, det = cofactors(m[:3, :3])
    if det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    inv = np.eye(4)
    inv[:3, :3] = cof.T / det
    inv[:3, 3] = -np.sum(inv[:3, :3] * m[:3, 3], axis=1)
    return inv
