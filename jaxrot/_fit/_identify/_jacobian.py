"""`identify`'s residuals with their Jacobian, in forward mode, experiment by experiment, and the
triangular factor of ``[J | r]`` that the Gauss–Newton step solves with (`_optimiser.search_step`)."""

import jax
import jax.numpy as jnp

from ..._inertia import body_inertia
from .._optimiser import triangular_factor
from ._model import _node_states, _one, _parameters, split


def n_dynamic(layout):
    """``(head, own)``: how many leading entries of the head and of each block move the rollout (the
    inertia, the ``args`` leaves, ``δq₀``, ``ω₀``); the rest (the sensor parameters) only the readings."""
    leaves = sum(layout.leaves[index].size for index, _ in layout.shared_leaves)
    return layout.n_inertia + leaves, 6 + sum(layout.leaves[index].size for index in layout.own_leaves)


def residuals_and_jacobian(phi, model):
    """`residuals`, their Jacobian ``(m, len(φ))`` and `states`: `residuals_jacobian_factor`'s first three."""
    return residuals_jacobian_factor(phi, model)[:3]


def residuals_jacobian_factor(phi, model):
    """`residuals`, their Jacobian ``(m, len(φ))``, `states` and the triangular factor of ``[J | r]``
    (`_block_factor`), in forward mode, experiment by experiment.

    Experiment ``j`` depends on the head of ``φ`` and on its own block only, so its residuals carry
    ``n_head + n_own`` tangents instead of ``len(φ)`` (15 instead of 27 for the three-manoeuvre
    satellite); the zero blocks of the other experiments are filled in afterwards.

    The rollout itself carries fewer: the sensor parameters (gyro bias, scale and delay, the tracker's
    mounting and delay) do not move the modelled states at the nodes, only how the sensors read them.
    So the nodes' states ``x`` and their tangents ``T = ∂x/∂θ`` are computed with the ``n_dynamic``
    tangents of what moves them (`n_dynamic`), and the readings are then differentiated in all
    tangents through ``x + T (θ − θ₀)``, which at ``θ₀`` has the nodes' values and derivatives: the
    chain rule, exactly. On MuJoCo's three manoeuvres with real sensors (10 000 steps each) the rollout
    then carries 12 tangents instead of 23. The modelled states ride along (the rollout's primal), so
    a fit needs no separate program for them.
    """
    layout = model.layout
    head, own = split(phi, layout)
    k = layout.n_experiments
    dyn_head, dyn_own = n_dynamic(layout)

    def direct(own, d):  # no sensor parameters: every tangent moves the rollout
        def twice(head, own):
            r, q, omega = _one(head, own, d, model)
            r = r.reshape(-1)
            return r, (r, q, omega)

        (j_head, j_own), (r, q, omega) = jax.jacfwd(twice, argnums=(0, 1), has_aux=True)(head, own)
        return r, j_head, j_own, q, omega

    def one(own, d):
        def rollout(dynamic_head, dynamic_own):
            h = jnp.concatenate([dynamic_head, head[dyn_head:]])
            o = jnp.concatenate([dynamic_own, own[dyn_own:]])
            inertia, args, _, q0, omega0 = _parameters(h, o, d, layout)
            nodes = _node_states(model, body_inertia(inertia), args, q0, omega0, d)
            return nodes, nodes

        # T: ((N + 1, 4, dyn_head), (N + 1, 4, dyn_own)) for q, the same for ω.
        tangents, (q_nodes, omega_nodes) = jax.jacfwd(rollout, argnums=(0, 1), has_aux=True)(
            head[:dyn_head], own[:dyn_own]
        )

        def readings(h, o):
            moved = h[:dyn_head] - head[:dyn_head], o[:dyn_own] - own[:dyn_own]  # zero at φ, not its tangent

            def node_at(j):
                q = q_nodes[j] + sum(t[j] @ m for t, m in zip(tangents[0], moved, strict=True))
                omega = omega_nodes[j] + sum(t[j] @ m for t, m in zip(tangents[1], moved, strict=True))
                return q, omega

            r, q, omega = _one(h, o, d, model, node_at)
            r = r.reshape(-1)
            return r, (r, q, omega)

        (j_head, j_own), (r, q, omega) = jax.jacfwd(readings, argnums=(0, 1), has_aux=True)(head, own)
        return r, j_head, j_own, q, omega

    # (k, m), (k, m, n_head), (k, m, n_own), (k, P + 1, 4), (k, P + 1, 3)
    split_rollout = (dyn_head, dyn_own) != (head.size, own.shape[1])
    r, j_head, j_own, q, omega = jax.vmap(one if split_rollout else direct)(own, model.data)
    m, width = r.shape[1], j_own.shape[2]
    eye = jnp.eye(k, dtype=phi.dtype)
    # (k, m, width) → (k m, k width): experiment j's block in columns j width … (j + 1) width − 1
    blocks = (j_own[:, :, None, :] * eye[:, None, :, None]).reshape(k * m, k * width)
    jac = jnp.concatenate([j_head.reshape(k * m, -1), blocks], axis=1)
    return r.reshape(-1), jac, (q, omega), _block_factor(r, j_head, j_own)


def _block_factor(r, j_head, j_own):
    """The triangular factor ``(n + 1, n + 1)`` of ``[J | r]`` from each experiment's rows, or None.

    Experiment ``j``'s rows are zero outside the head's and its own columns, so each experiment's
    ``[J_head | J_own | r]`` ``(m, w + 1)`` is reduced to its triangular factor first (``w = n_head +
    n_own``), and the stacked factors, placed in their columns, are reduced once more: ``[J | r] =
    diag(Q_j) [R_j's stacked]``, so the last factor is ``[J | r]``'s (up to the rows' signs, which the
    step does not see). A Householder QR of ``m`` rows costs ``m n²``: this is ``k m w²`` instead of
    ``k m n²``, 3.4× less on MuJoCo's real-sensor problem (``w = 23``, ``n = 41``), where the QR of
    the whole 27 000 × 42 matrix took as long as a third of the Jacobian evaluation.
    """
    k, m, width = j_own.shape
    w = j_head.shape[2] + width
    if m < w + 1:  # an experiment with fewer residuals than its columns: no triangular factor of its own
        return None
    tri = jax.vmap(triangular_factor)(jnp.concatenate([j_head, j_own, r[:, :, None]], axis=2))
    eye = jnp.eye(k, dtype=r.dtype)
    rows = k * (w + 1)
    own = (tri[:, :, None, j_head.shape[2] : w] * eye[:, None, :, None]).reshape(rows, k * width)
    stacked = jnp.concatenate(
        [tri[:, :, : j_head.shape[2]].reshape(rows, -1), own, tri[:, :, w:].reshape(rows, 1)], 1
    )
    return triangular_factor(stacked)
