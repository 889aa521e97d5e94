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
        control = jax.vmap(lambda column: jnp.interp(t, t_c, column), in_axes=1)(tau_c)
        if self.user is None:
            return control
        return jnp.asarray(self.user(t, q, omega, user_args), control.dtype) + control


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


def unpack(phi, layout):
    """``(inertia (3, 3), args, δq₀ (k, 3), ω₀ (k, 3))`` from ``φ``."""
    i = layout.n_inertia
    inertia = inertia_of(phi[:i], layout)
    leaves = list(layout.leaves)
    for index, positive in layout.free_leaves:
        like = leaves[index]
        value = phi[i : i + like.size].reshape(like.shape)
        leaves[index] = jnp.exp(value) if positive else value
        i += like.size
    args = jax.tree_util.tree_unflatten(layout.treedef, leaves)
    k = layout.n_experiments
    dq = phi[i : i + 3 * k].reshape(k, 3)
    omega0 = phi[i + 3 * k : i + 6 * k].reshape(k, 3)
    return inertia, args, dq, omega0


def states(phi, model):
    """Modelled ``q (k, P + 1, 4)``, ``ω (k, P + 1, 3)`` (world frame) at every padded sample."""
    inertia, args, dq, omega0 = unpack(phi, model.layout)
    d = model.data
    q0 = quat.multiply(quat.exp(dq), d.q_start)
    prepared = body_inertia(inertia)

    def one(q0, omega0, t, control_t, control_tau):
        run_args = args if control_t is None else (args, control_t, control_tau)
        return sample_states(model.scheme, model.torque, run_args, prepared, q0, omega0, t, model.substeps)

    axes = (0, 0, 0, None if d.control_t is None else 0, None if d.control_tau is None else 0)
    return jax.vmap(one, in_axes=axes)(q0, omega0, d.t, d.control_t, d.control_tau)


def raw_residuals(phi, model):
    """Unwhitened misfits ``(k, 3 kinds, P + 1, 3)``, zero where a kind or sample is not observed."""
    q, omega = states(phi, model)
    d = model.data
    r_q = signed_vector(q, d.q)
    r_omega = quat.rotate(quat.conjugate(q), omega) - d.omega_body
    r_direction = quat.rotate(q, d.body_vector[:, None, :]) - d.direction
    r = jnp.stack([r_q, r_omega, r_direction], axis=1)
    return r * d.weight[..., None]


def residuals(phi, model):
    """The whitened residual vector (each misfit over its noise σ) whose sum of squares is minimised."""
    r = raw_residuals(phi, model) / model.data.sigma[:, :, None, None]
    return r.reshape(-1)


def pad_rows(x, length):
    """``x`` ``(n, ...)`` padded to ``length`` rows by repeating its last row."""
    return np.concatenate([x, np.repeat(x[-1:], length - x.shape[0], axis=0)])
