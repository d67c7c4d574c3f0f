"""Sparse symmetric positive-definite direct solves with a reusable analysis.

Contact and Newton iterations change the stiffness matrix's values but never
its sparsity pattern, so the fill-reducing ordering and symbolic factorisation
are computed once (:meth:`SPDSolver.analyze`) and each new matrix costs only a
numerical Cholesky factorisation. MKL PARDISO (through pypardiso) does this on
both cores; SciPy's SuperLU is the fallback where MKL is not available.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

try:  # MKL is not available on every platform (e.g. ARM macOS)
    import pypardiso
    from pypardiso.pardiso_wrapper import PyPardisoError
except ImportError:  # pragma: no cover - exercised only without MKL
    pypardiso = None

_SPD_REAL = 2  # PARDISO matrix type: real symmetric positive definite
_NOT_POSITIVE_DEFINITE = -4  # PARDISO: zero or negative pivot


class NotPositiveDefinite(ArithmeticError):
    """The matrix handed to :meth:`SPDSolver.factorize` is not positive definite."""


class SPDSolver:
    """Factorise SPD matrices sharing one sparsity pattern; solve for many right-hand sides."""

    def __init__(self) -> None:
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self._upper: sp.csr_matrix | None = None
        self._lu = None
        self._pardiso = pypardiso.PyPardisoSolver(mtype=_SPD_REAL) if pypardiso is not None else None
        self.factorizations = 0
        self.solves = 0

    def __del__(self) -> None:
        # PARDISO keeps its factors outside Python's heap until told to release them
        if self._pardiso is not None and self._pattern is not None:
            try:
                self._pardiso.free_memory(everything=True)
            except Exception:  # interpreter shutdown: the library may already be gone
                pass

    @property
    def backend(self) -> str:
        return "mkl-pardiso" if self._pardiso is not None else "scipy-superlu"

    def factorize(self, matrix: sp.spmatrix) -> None:
        """Cholesky-factorise ``matrix`` (symmetric; only its upper triangle is read)."""
        upper = sp.triu(matrix, format="csr")
        upper.sort_indices()
        self.factorizations += 1
        if self._pardiso is None:
            from scipy.sparse.linalg import splu

            full = (upper + sp.triu(upper, k=1).T).tocsc()
            self._lu = splu(full)
            if np.any(self._lu.U.diagonal() <= 0) and (self._lu.perm_r == self._lu.perm_c).all():
                raise NotPositiveDefinite("stiffness matrix is not positive definite")
            return
        pattern = (upper.indptr, upper.indices)
        same_pattern = (self._pattern is not None and np.array_equal(pattern[0], self._pattern[0])
                        and np.array_equal(pattern[1], self._pattern[1]))
        self._pardiso.set_iparm(12, 0)
        self._pardiso.set_phase(22 if same_pattern else 12)
        try:
            self._pardiso._call_pardiso(upper, np.zeros((upper.shape[0], 1)))
        except PyPardisoError as error:
            self._pattern = None  # the analysis is redone on the next call
            if error.value == _NOT_POSITIVE_DEFINITE:
                raise NotPositiveDefinite("stiffness matrix is not positive definite") from None
            raise
        self._pattern, self._upper = pattern, upper

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation; ``rhs`` may be (n,) or (n, k)."""
        self.solves += 1 if rhs.ndim == 1 else rhs.shape[1]
        if self._pardiso is None:
            return self._lu.solve(rhs)
        self._pardiso.set_phase(33)
        return self._pardiso._call_pardiso(self._upper, np.asfortranarray(rhs, dtype=np.float64))
