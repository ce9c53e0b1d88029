"""Bounded work: the products with the affinity one eigensolve may make, and Cancel.

Every eigensolve of a segment (:mod:`.eigensolver`, :mod:`.spectral`) may make at most
``max_products`` products with the affinity (:data:`MAX_CUT_PRODUCTS` by default; one
product is one vector), all solvers of the solve together; :class:`Budget` counts them
and calls ``cancel()`` before each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..errors import Cancelled, PolarsegError

if TYPE_CHECKING:
    from scipy.sparse.linalg import LinearOperator

#: Default cap on the products with the affinity one segment's eigensolve may make, all
#: solvers together (module docstring: "Bounded work"); above the largest solves of
#: normal inputs (docs/performance.md, "Measurements behind the code").
MAX_CUT_PRODUCTS = 2_000


#: Smallest ``max_products`` accepted (the block solver's first step needs a few).
MIN_CUT_PRODUCTS = 20


class OutOfProducts(Exception):
    """A solver asked for more products than its budget has left."""


class Budget:
    """The products with the affinity one eigensolve may still make; checks Cancel.

    Every solver charges its products here before making them (:meth:`take`, one per
    vector), which is also where ``cancel()`` is called.

    Parameters
    ----------
    limit : int
        Products the whole solve may make.
    cancel : callable() -> bool, optional
        Returning True raises :class:`~napari_polarseg.engine.errors.Cancelled`.
    """

    def __init__(self, limit: int, cancel: Callable[[], bool] | None = None) -> None:
        self.limit = int(limit)
        self.cancel = cancel
        self.used = 0
        #: a solver was refused products: the solve ended on a best-so-far vector
        self.capped = False

    def take(self, columns: int, stop: int | None = None) -> bool:
        """Charge ``columns`` products if they fit below ``stop`` (default: the limit).

        Returns False, and marks the solve as capped when ``stop`` is the limit, if they
        do not fit.
        """
        if self.cancel is not None and self.cancel():
            raise Cancelled("the normalized cut was cancelled")
        end = self.limit if stop is None else min(stop, self.limit)
        if self.used + columns > end:
            self.capped = self.capped or end == self.limit
            return False
        self.used += columns
        return True

    def operator(
        self, n: int, product: Callable[[np.ndarray], np.ndarray], stop: int | None = None
    ) -> LinearOperator:
        """``product`` (x ↦ A x on (n,) vectors) as an operator that charges each call;
        past the budget (or ``stop``) it raises :class:`OutOfProducts`."""

        def matvec(x: np.ndarray) -> np.ndarray:
            if not self.take(1, stop):
                raise OutOfProducts
            return product(np.ravel(x))

        from scipy.sparse.linalg import LinearOperator  # start-up cost paid when used

        return LinearOperator((n, n), matvec=matvec, dtype=float)


def check_products(max_products: int) -> int:
    if not isinstance(max_products, (int, np.integer)) or max_products < MIN_CUT_PRODUCTS:
        raise PolarsegError(
            f"max_products must be an integer >= {MIN_CUT_PRODUCTS}, got {max_products!r}"
        )
    return int(max_products)
