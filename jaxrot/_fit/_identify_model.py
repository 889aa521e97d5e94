"""`identify`'s model: the parameter vector, the padded experiments, and the whitened residuals.

The optimiser works on one vector ``φ = [inertia | free args | δq₀ per experiment |
ω₀ per experiment]``. Every ``φ`` is physical: the tensor comes from
`inertia_from_cholesky` (or, with the axes known, moments ``s₂+s₃, s₁+s₃, s₁+s₂``
of squared second moments ``sᵢ = pᵢ²``), a positive argument is ``exp`` of its
coordinate, and the initial orientation is ``exp(δq₀) ⊗ q_start``.

The experiments are padded to a common number of samples and control samples
and run under one ``vmap``: padding repeats the last time (zero-length steps
leave the state alone) and carries weight 0, as do NaN samples and absent kinds.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._inertia import body_inertia
from ._objective import sample_states, signed_vector
from ._parameterisation import inertia_from_cholesky


class ControlledTorque(eqx.Module):
    """The user's torque model plus the experiment's sampled control torque (world frame).

    Called with ``args = (user_args, t_c (m,), tau_c (m, 3))``; ``tau_c`` is
    interpolated linearly in time and held constant outside ``t_c``.
    """

    user: object = eqx.field(static=True)

    def __call__(self, t, q, omega, args):
        user_args, t_c, tau_c = args
        control = interpolate_control(t, t_c, tau_c)
        if self.user is None:
            return control
        return jnp.asarray(self.user(t, q, omega, user_args), control.dtype) + control


# Up to this many control samples the interpolation is a sum of ramps (one fused kernel, O(M));
# beyond, jnp.interp's binary search (a while loop of log₂ M passes, each a handful of kernels).
RAMP_SUM_MAX_SAMPLES = 64


def interpolate_control(t, t_c, tau_c):
    """``tau_c (M, 3)`` sampled at strictly increasing ``t_c (M,)``, linear in between, held outside.

    For short records, ``τ(t) = τ₀ + Σⱼ clip((t − tⱼ) / (tⱼ₊₁ − tⱼ), 0, 1) (τⱼ₊₁ − τⱼ)``: the same
    values as `jnp.interp` without its search loop, which inside `identify`'s rollout ran once per
    stage evaluation, 4 passes of 5 kernels each for 13 control samples (on XLA:CPU each kernel costs
    a fixed launch overhead; the rollout is bound by their count, not by arithmetic).
    """
    if t_c.shape[0] > RAMP_SUM_MAX_SAMPLES:
        return jax.vmap(lambda column: jnp.interp(t, t_c, column), in_axes=1)(tau_c)
    ramps = jnp.clip((t - t_c[:-1]) / (t_c[1:] - t_c[:-1]), 0, 1)
    return tau_c[0] + jnp.sum(ramps[:, None] * (tau_c[1:] - tau_c[:-1]), axis=0)


class Data(eqx.Module):
    """The experiments, padded to ``P + 1`` samples and ``M`` control samples: leading axis ``k``."""

    t: jax.Array  # (k, P + 1)
    q: jax.Array  # (k, P + 1, 4)   NaN and absent samples replaced by the identity (weight 0)
    omega_body: jax.Array  # (k, P + 1, 3)
    direction: jax.Array  # (k, P + 1, 3)
    weight: jax.Array  # (k, 3, P + 1)  per kind (q, omega_body, direction): 1 observed, 0 not
    body_vector: jax.Array  # (k, 3)
    sigma: jax.Array  # (k, 3) noise standard deviation per kind (1 where absent)
    q_start: jax.Array  # (k, 4) the orientation δq₀ is measured from
    control_t: jax.Array | None  # (k, M)
    control_tau: jax.Array | None  # (k, M, 3)


class Layout(eqx.Module):
    """How ``φ`` maps to the physical parameters (static), and the fixed values it needs."""

    inertia_mode: str = eqx.field(static=True)  # "tensor", "moments" or "fixed"
    unit_scale: bool = eqx.field(static=True)  # torque-free: the tensor's scale is fixed, not fitted
    n_inertia: int = eqx.field(static=True)
    free_leaves: tuple = eqx.field(static=True)  # ((leaf index, positive), ...)
    treedef: object = eqx.field(static=True)
    n_experiments: int = eqx.field(static=True)
    inertia0: jax.Array  # (3, 3) fixed tensor ("fixed"), or the known axes ("moments")
    lead: jax.Array  # the fixed first inertia coordinate when unit_scale (L₀₀ or p₀)
    trace0: jax.Array  # the trace a scale-free tensor is given
    leaves: tuple  # args' leaves at the start (the fixed ones are used as they are)


class Model(eqx.Module):
    """Everything the residuals need: data, layout and the static configuration of the rollout."""

    data: Data
    layout: Layout
    scheme: object = eqx.field(static=True)
    torque: object = eqx.field(static=True)
    substeps: int = eqx.field(static=True)


def inertia_of(phi_inertia, layout):
    """The body-frame tensor ``(3, 3)`` from its coordinates."""
    if layout.inertia_mode == "fixed":
        return layout.inertia0
    coords = phi_inertia
    if layout.unit_scale:
        coords = jnp.concatenate([layout.lead[None].astype(coords.dtype), coords])
    if layout.inertia_mode == "tensor":
        inertia = inertia_from_cholesky(coords, unit_trace=layout.unit_scale)
    else:
        s = coords**2
        moments = jnp.stack([s[1] + s[2], s[0] + s[2], s[0] + s[1]])
        axes = layout.inertia0.astype(coords.dtype)
        inertia = (axes * moments[None, :]) @ axes.T
        if layout.unit_scale:
            inertia = inertia / jnp.trace(inertia)
    return inertia * layout.trace0 if layout.unit_scale else inertia


def _shared(phi, layout):
    """``(inertia (3, 3), args)`` from ``φ``'s shared head: the inertia and free-argument coordinates."""
    i = layout.n_inertia
    inertia = inertia_of(phi[:i], layout)
    leaves = list(layout.leaves)
    for index, positive in layout.free_leaves:
        like = leaves[index]
        value = phi[i : i + like.size].reshape(like.shape)
        leaves[index] = jnp.exp(value) if positive else value
        i += like.size
    return inertia, jax.tree_util.tree_unflatten(layout.treedef, leaves)


def n_shared(layout):
    """Length of ``φ``'s shared head: the rest is ``δq₀`` (k, 3) then ``ω₀`` (k, 3)."""
    return layout.n_inertia + sum(layout.leaves[index].size for index, _ in layout.free_leaves)


def _split(phi, layout):
    """``φ`` as its shared head, ``δq₀ (k, 3)`` and ``ω₀ (k, 3)``."""
    i, k = n_shared(layout), layout.n_experiments
    return phi[:i], phi[i : i + 3 * k].reshape(k, 3), phi[i + 3 * k : i + 6 * k].reshape(k, 3)


def unpack(phi, layout):
    """``(inertia (3, 3), args, δq₀ (k, 3), ω₀ (k, 3))`` from ``φ``."""
    shared, dq, omega0 = _split(phi, layout)
    return *_shared(shared, layout), dq, omega0


def _one_states(shared, dq, omega0, d, model):
    """Modelled ``q (P + 1, 4)``, ``ω (P + 1, 3)`` (world) of experiment ``d`` from its ``(δq₀, ω₀)``."""
    inertia, args = _shared(shared, model.layout)
    q0 = quat.multiply(quat.exp(dq), d.q_start)
    run_args = args if d.control_t is None else (args, d.control_t, d.control_tau)
    return sample_states(
        model.scheme, model.torque, run_args, body_inertia(inertia), q0, omega0, d.t, model.substeps
    )


def _one_residuals(shared, dq, omega0, d, model):
    """One experiment's whitened misfits ``(3 kinds, P + 1, 3)``, zero where not observed."""
    return _misfits(*_one_states(shared, dq, omega0, d, model), d)


def _misfits(q, omega, d):
    """Whitened misfits ``(3 kinds, P + 1, 3)`` of the modelled ``q``, ``ω`` to experiment ``d``."""
    r_q = signed_vector(q, d.q)
    r_omega = quat.rotate(quat.conjugate(q), omega) - d.omega_body
    r_direction = quat.rotate(q, d.body_vector[None, :]) - d.direction
    r = jnp.stack([r_q, r_omega, r_direction])
    return r * (d.weight / d.sigma[:, None])[..., None]


def states(phi, model):
    """Modelled ``q (k, P + 1, 4)``, ``ω (k, P + 1, 3)`` (world frame) at every padded sample."""
    shared, dq, omega0 = _split(phi, model.layout)
    one = lambda dq, omega0, d: _one_states(shared, dq, omega0, d, model)  # noqa: E731
    return jax.vmap(one)(dq, omega0, model.data)


def residuals(phi, model):
    """The whitened residual vector (each misfit over its noise σ) whose sum of squares is minimised.

    Experiment-major: experiment ``j``'s ``3 (P + 1) 3`` misfits, kind by kind, then ``j + 1``'s.
    """
    shared, dq, omega0 = _split(phi, model.layout)
    one = lambda dq, omega0, d: _one_residuals(shared, dq, omega0, d, model)  # noqa: E731
    return jax.vmap(one)(dq, omega0, model.data).reshape(-1)


def residuals_and_jacobian(phi, model):
    """`residuals`, their Jacobian ``(m, len(φ))`` and `states`, in forward mode, experiment by experiment.

    Experiment ``j`` depends on the shared head of ``φ`` and on its own ``(δq₀, ω₀)``
    only, so each rollout carries ``n_shared + 6`` tangents instead of ``len(φ)``
    (15 instead of 27 for the three-manoeuvre satellite); the zero blocks of the
    other experiments' starts are filled in afterwards. The modelled states ride
    along (the rollout's primal), so a fit needs no separate program for them.
    """
    shared, dq, omega0 = _split(phi, model.layout)
    k = model.layout.n_experiments

    def one(dq, omega0, d):
        def twice(shared, own):
            q, omega = _one_states(shared, own[:3], own[3:], d, model)
            r = _misfits(q, omega, d).reshape(-1)
            return r, (r, q, omega)

        (j_shared, j_own), (r, q, omega) = jax.jacfwd(twice, argnums=(0, 1), has_aux=True)(
            shared, jnp.concatenate([dq, omega0])
        )
        return r, j_shared, j_own, q, omega

    # (k, m), (k, m, n_shared), (k, m, 6), (k, P + 1, 4), (k, P + 1, 3)
    r, j_shared, j_own, q, omega = jax.vmap(one)(dq, omega0, model.data)
    eye = jnp.eye(k, dtype=phi.dtype)
    m = r.shape[1]

    def block_diagonal(block):  # (k, m, 3) → (k m, 3 k), experiment j's block in columns 3j … 3j + 2
        return (block[:, :, None, :] * eye[:, None, :, None]).reshape(k * m, 3 * k)

    jac = jnp.concatenate(
        [j_shared.reshape(k * m, -1), block_diagonal(j_own[..., :3]), block_diagonal(j_own[..., 3:])], axis=1
    )
    return r.reshape(-1), jac, (q, omega)


def pad_rows(x, length):
    """``x`` ``(n, ...)`` padded to ``length`` rows by repeating its last row."""
    return np.concatenate([x, np.repeat(x[-1:], length - x.shape[0], axis=0)])
