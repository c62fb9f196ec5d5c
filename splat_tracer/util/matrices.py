"""Small matrix helpers that never call BLAS or LAPACK.

numpy hands `np.linalg.inv` -- even of a 4x4 matrix: numpy 1.26's OpenBLAS 0.3.23 runs its
`dgesv` threaded at any size -- and a matrix product of many rows (an (N, 3) x (3, 3)
transform) to OpenBLAS, which wakes its thread pool; the pool's threads then spin
(sched_yield) for about a tenth of a second before they sleep. Blender's own numpy is the
same OpenBLAS build, so a render that inverted its camera matrix just before starting lost
up to a third of the machine to those spinning threads while it rendered (measured on the
bunny-on-a-floor frame: a third of the samples during the render's first 0.2 s went to
OpenBLAS' thread on 2 cores). The per-frame and per-import matrix work is done here
instead: it is tiny (a 4x4 inverse) or a column at a time (a row transform).
"""
from __future__ import annotations

import numpy as np


def inverse(m) -> np.ndarray:
    """The inverse of a square float64 matrix by Gauss-Jordan elimination with partial
    pivoting, in Python floats (double precision, as LAPACK's). Raises
    np.linalg.LinAlgError for a singular matrix, as np.linalg.inv does. Meant for 3x3 and
    4x4 matrices: its cost grows as n^3 Python operations."""
    a = np.asarray(m, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"inverse needs a square matrix, got shape {a.shape}")
    n = a.shape[0]
    rows = [list(map(float, a[i])) + [1.0 if j == i else 0.0 for j in range(n)] for i in range(n)]
    for col in range(n):
        pivot = max(range(col, n), key=lambda r: abs(rows[r][col]))
        if rows[pivot][col] == 0.0 or not np.isfinite(rows[pivot][col]):
            raise np.linalg.LinAlgError("Singular matrix")
        rows[col], rows[pivot] = rows[pivot], rows[col]
        p = rows[col]
        inv_p = 1.0 / p[col]
        p[:] = [v * inv_p for v in p]
        for r in range(n):
            if r != col and rows[r][col] != 0.0:
                f = rows[r][col]
                rows[r] = [v - f * w for v, w in zip(rows[r], p)]
    return np.array([row[n:] for row in rows], dtype=np.float64)


def transform_rows(points: np.ndarray, m) -> np.ndarray:
    """points @ m.T (each row transformed by the small matrix m) in float64, as `@` with a
    float64 matrix gives it, computed a column at a time: no BLAS call and no (N, 3)
    temporaries."""
    p = np.asarray(points)
    mat = np.asarray(m, dtype=np.float64)
    if p.ndim != 2 or mat.ndim != 2 or p.shape[1] != mat.shape[1]:
        raise ValueError(f"cannot transform rows of shape {p.shape} by a {mat.shape} matrix")
    out = np.empty((len(p), mat.shape[0]), dtype=np.float64)
    for i in range(mat.shape[0]):
        acc = np.multiply(p[:, 0], mat[i, 0], dtype=np.float64)
        for k in range(1, mat.shape[1]):
            acc += np.multiply(p[:, k], mat[i, k], dtype=np.float64)
        out[:, i] = acc
    return out


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """(N,3,3) rotation matrices of unit quaternions (w, x, y, z); columns are the axes."""
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)
