"""An explicit exponential Runge–Kutta tableau: coefficient functions as sums of φ-functions, their
weights at a step's ``z = −hL``, and a row's combination of the earlier stages (`_exponential`)."""

import math
from typing import NamedTuple

import numpy as np

from ._lie_runge_kutta import add_terms
from ._phi import phi_functions


Term = tuple[float, int, float]  # (coefficient, k, node): coefficient · φ_k(node · z)


class ExponentialTableau(NamedTuple):
    """An explicit exponential Runge–Kutta method: its coefficient functions as sums of φ-functions.

    Attributes:
        c: the nodes of stages 2, …, s (stage 1 is at 0).
        a: for each of stages 2, …, s, ``{j: terms}``: ``a_ij(z) = Σ coefficient · φ_k(node · z)``
            over its terms ``(coefficient, k, node)`` (``j`` counts stages from 0).
        b: ``{j: terms}``, the weights of the step.
        b_embedded: ``{j: terms}``, the weights of an embedded method of lower order on the same
            stages (its difference from ``b`` is the step's error estimate), or None.
    """

    c: tuple[float, ...]
    a: tuple[dict[int, tuple[Term, ...]], ...]
    b: dict[int, tuple[Term, ...]]
    b_embedded: dict[int, tuple[Term, ...]] | None = None

    @property
    def num_stages(self) -> int:
        return len(self.c) + 1

    def rows(self):
        """``(node, row)`` of stages 2, …, s, then ``(1.0, b)``."""
        return [*zip(self.c, self.a, strict=True), (1.0, self.b)]

    def embedded(self) -> "ExponentialTableau":
        """The embedded weights as a tableau of one row (`_weights` of it: the embedded step's weights)."""
        return ExponentialTableau(c=(), a=(), b=self.b_embedded)

    def k_max(self) -> int:
        """The highest φ-function the ``Θ``-rows need (one above the highest term)."""
        return 1 + max(k for _, row in self.rows() for terms in row.values() for _, k, _ in terms)

    def check(self):
        """``Σ_j a_ij(z) = c_i φ_1(c_i z)``, ``Σ_j b_j(z) = φ_1(z)`` (and ``b_embedded``) at a few ``z``."""
        embedded = [] if self.b_embedded is None else [(1.0, self.b_embedded)]
        for node, row in self.rows() + embedded:
            for z in (0.0, -0.3, -4.0, -60.0):
                total = sum(_term_value(t, z) for terms in row.values() for t in terms)
                expected = node * float(phi_functions(np.float64(node * z), 1, np)[1])
                if abs(total - expected) > 1e-12 * max(1.0, abs(expected)):
                    raise TypeError(
                        f"exponential tableau row at node {node}: Σ a(z={z}) = {total}, not {expected}."
                    )


def _term_value(term, z):
    coefficient, k, node = term
    return coefficient * float(phi_functions(np.float64(node * z), k, np)[k])


def _weights(tableau: ExponentialTableau, z):
    """For each row: ``(e^{c z}, c φ_1(c z), {j: a_ij(z)}, {j: ã_ij(z)}, {j: a_ij(0)})``.

    ``z = −hL`` ``(3,)``, or None (no friction): then the Python numbers of ``z = 0``."""
    k_max = tableau.k_max()
    nodes = sorted(
        {node for node, _ in tableau.rows()}
        | {t[2] for _, r in tableau.rows() for ts in r.values() for t in ts}
    )
    if z is None:
        phis = {node: [1 / math.factorial(k) for k in range(k_max + 1)] for node in nodes}
    else:
        phis = {node: phi_functions(node * z, k_max) for node in nodes}
    rows = []
    for node, row in tableau.rows():
        a = {j: sum(c * phis[nu][k] for c, k, nu in terms) for j, terms in row.items()}
        a_int = {j: sum(c * nu * phis[nu][k + 1] for c, k, nu in terms) for j, terms in row.items()}
        a_zero = {j: sum(c / math.factorial(k) for c, k, _ in terms) for j, terms in row.items()}
        rows.append((phis[node][0], node * phis[node][1], a, a_int, a_zero))
    return rows


def _sum(weights, values):
    """``Σ_j weights[j] · values[j]`` over the nonzero weights, or None."""
    return add_terms([w * values[j] for j, w in weights.items() if not (isinstance(w, float) and w == 0.0)])


def _combine(row, deviation0, forcings, rotation_terms, h):
    """``(Θ, V)`` of a stage (or output) row of `_weights` from the earlier stages' values."""
    decay, transient, a, a_int, a_zero = row
    deviation = decay * deviation0
    increment = _sum(a, forcings)
    if increment is not None:
        deviation = deviation + h * increment
    theta = (h * transient) * deviation0
    for weights, values, scale in ((a_int, forcings, h * h), (a_zero, rotation_terms, h)):
        part = _sum(weights, values)
        if part is not None:
            theta = theta + scale * part
    return theta, deviation
