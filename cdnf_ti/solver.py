"""Per-frame fixed-point orchestration shared by every C-DNF backend.

A backend supplies ``iterate(lam) -> residuals``: one relaxed update
``u <- u + lam (F(u) - u)`` of one or more coupled fields, returning the
residual ``max |F(u) - u|`` of each field *before* the update. The controller
here decides when to stop, and damps (halves ``lam``) when the residual stops
falling, so both backends follow the same schedule and an unconverged field is
always reported, never returned silently.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np


@dataclass
class SolveReport:
    """Outcome of one fixed-point solve.

    Attributes
    ----------
    iterations : tuple of int
        Per field, the number of updates until its residual fell below ``tol``
        (``max_iter`` when it never did).
    residuals : tuple of float
        Per field, the last residual ``max |F(u) - u|`` measured.
    converged : bool
        Every field reached ``tol``.
    damping : float
        The relaxation ``lambda`` in force at the end.
    """

    iterations: tuple[int, ...]
    residuals: tuple[float, ...]
    converged: bool
    damping: float


def solve_fixed_point(
    iterate: Callable[[float], Sequence[float]],
    n_fields: int,
    tol: float,
    max_iter: int,
    damping: float = 1.0,
    min_damping: float = 1.0 / 64.0,
    stall_patience: int = 4,
) -> SolveReport:
    """Iterate ``iterate(lam)`` until every residual is below ``tol``.

    Parameters
    ----------
    iterate : callable
        ``iterate(lam)`` performs one relaxed update of all fields and returns
        their residuals (length ``n_fields``).
    n_fields : int
        Number of fields updated together (2 for ON/OFF, 1 for Summation).
    tol : float
        Convergence tolerance on each residual.
    max_iter : int
        Maximum number of updates.
    damping : float
        Initial relaxation ``lambda``.
    min_damping : float
        Lower bound for ``lambda``.
    stall_patience : int
        After this many consecutive updates whose largest residual did not fall
        below the best seen so far, ``lambda`` is halved.

    Returns
    -------
    SolveReport
    """
    lam = float(damping)
    first_ok = [0] * n_fields
    best = np.inf
    stalled = 0
    res: Sequence[float] = [np.inf] * n_fields
    for k in range(1, max_iter + 1):
        res = iterate(lam)
        for f in range(n_fields):
            if first_ok[f] == 0 and res[f] < tol:
                first_ok[f] = k
        worst = max(res)
        if worst < tol:
            return SolveReport(tuple(first_ok), tuple(float(r) for r in res), True, lam)
        if not np.isfinite(worst):
            break
        if worst < best:
            best = worst
            stalled = 0
        else:
            stalled += 1
            if stalled >= stall_patience and lam > min_damping:
                lam = max(lam * 0.5, min_damping)
                stalled = 0
                best = worst
    iters = tuple(first_ok[f] if first_ok[f] else max_iter for f in range(n_fields))
    return SolveReport(iters, tuple(float(r) for r in res), False, lam)
