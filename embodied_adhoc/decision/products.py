"""Matrix products with one fixed summation order: the same bits on every host, whatever BLAS kernel it picks.

BLAS kernels (OpenBLAS picks one per CPU: SkylakeX, Haswell, Sandybridge, ...) sum a dot product in blocks whose
order depends on the kernel, so its last bits do too. The solvers decide near-ties with these products (which
vector is best at a belief, whether a backup improves it, which action a policy takes), and exact ties are common
in structured models, so a BLAS product makes a solve, and every table built on it, depend on the host.

:func:`dot` computes ``left @ right`` with scipy's CSR kernels instead: element ``(i, k)`` is
``sum_j left[i, j] * right[j, k]`` accumulated from 0 over the nonzeros of row ``i`` in increasing ``j``, one
rounded product and one rounded sum at a time. scipy's sparse kernels have no run-time CPU dispatch, so the result
is the same on any x86-64 host, and a row's value is the same whether it is computed alone or with other rows, or
against one column or many. Zeros of ``left`` are skipped, which also makes products with sparse beliefs cheap.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def dot(left: np.ndarray | sp.spmatrix | sp.sparray, right: np.ndarray) -> np.ndarray:
    """``left @ right`` (dense ``right``, 1-D or 2-D; ``left`` dense 1-D or 2-D, or sparse) in the fixed order
    above, as a dense array of the shape ``left @ right`` has.

    A 1-D ``left`` (one belief) reads only the rows of ``right`` on its support, so a transposed, non-contiguous
    ``right`` (``alphas.T``) costs no copy of the whole matrix; a 2-D ``right`` should be C-contiguous otherwise
    (scipy copies it per call)."""
    right = np.asarray(right)
    if sp.issparse(left):
        return np.asarray(left @ np.ascontiguousarray(right))
    left = np.asarray(left)
    if left.ndim == 1:
        support = np.flatnonzero(left)
        row = sp.csr_matrix(
            (left[support], np.arange(support.size), np.array([0, support.size])), shape=(1, support.size)
        )
        return np.asarray(row @ np.ascontiguousarray(right[support]))[0]
    return np.asarray(sp.csr_matrix(left) @ np.ascontiguousarray(right))


def transposed(matrix: np.ndarray) -> np.ndarray:
    """``matrix.T`` as a C-contiguous array: the right operand of :func:`dot` for ``beliefs @ alphas.T``."""
    return np.ascontiguousarray(np.asarray(matrix).T)
