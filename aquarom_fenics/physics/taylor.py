"""Taylor polynomials in the design change Δξ: how a term's reduced tensors depend on the shape.

Plain numpy: each force term stores its reduced tensors as a :class:`Taylor`; the projection
(:mod:`aquarom_fenics.reduction.projection`) computes their coefficients.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class Taylor:
    """T(Δξ) = T0 + Σ_k Δξ_k T1[k] + ½ Σ_kl Δξ_k Δξ_l T2[k, l] (T1, T2 absent below the order)."""

    constant: np.ndarray
    first: np.ndarray | None = None
    second: np.ndarray | None = None

    def at(self, delta: np.ndarray) -> np.ndarray:
        value = np.array(self.constant, dtype=float)
        if self.first is not None and delta.size:
            value = value + np.tensordot(delta, self.first, axes=1)
        if self.second is not None and delta.size:
            value = value + 0.5 * np.tensordot(delta, np.tensordot(delta, self.second, axes=1), axes=1)
        return value

    def gradient(self, delta: np.ndarray) -> np.ndarray:
        """∂T/∂ξ_k at Δξ, shape (p, ...)."""
        if self.first is None:
            return np.zeros((delta.size,) + np.shape(self.constant))
        value = np.array(self.first, dtype=float)
        if self.second is not None:
            value = value + np.tensordot(delta, self.second, axes=1)
        return value


def stack_taylor(parts: list[Taylor]) -> Taylor:
    """One Taylor of the stacked values: constant (n, ...), first (p, n, ...), second (p, p, n, ...)."""
    def stacked(name):
        values = [getattr(part, name) for part in parts]
        return None if values[0] is None else np.stack(values, axis=-np.ndim(parts[0].constant) - 1)
    return Taylor(np.stack([part.constant for part in parts]), stacked("first"), stacked("second"))


def taylor_of(evaluate: Callable[[tuple[int, ...]], tuple], n_parameters: int, order: int) -> list[Taylor]:
    """The Taylor in Δξ of each value of ``evaluate(indices)``, a tuple whose entries are the values'
    ξ-derivatives along e_k for k in ``indices`` (``()``: the values; ``(k,)``; ``(k, l)`` with k ≤ l),
    up to ``order``: T1[k] = evaluate((k,)), T2[k, l] = T2[l, k] = evaluate((k, l))."""
    p = n_parameters
    constant = evaluate(())
    first = second = [None] * len(constant)
    if order >= 1 and p:
        first = [np.stack(parts) for parts in zip(*(evaluate((k,)) for k in range(p)))]
    if order >= 2 and p:
        second = [np.empty((p, p) + np.shape(part)) for part in constant]
        for k in range(p):
            for l in range(k, p):
                for term, part in zip(second, evaluate((k, l))):
                    term[k, l] = term[l, k] = part
    return [Taylor(*parts) for parts in zip(constant, first, second)]
