"""`fit_inertia`'s residuals: rollouts of the `Model` from the fitted starts, misfits to the observations.

`residuals(params, model)` is the vector the Gauss–Newton of `_solve` minimises the sum of
squares of, with the predicted states; `objective` is the same sum as the mean weighted
misfit (with the continuity penalty of multiple shooting), differentiated by
`value_and_grad` for the optional Adam warm-up.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ... import quaternion as quat
from ..._inertia import body_inertia
from ..._state import RotState
from .._misfit import orientation_misfit, signed_vector
from .._parameterisation import inertia_from_cholesky


def _misfit(model, state, q_obs, omega_obs):
    r = orientation_misfit(state.q, q_obs)
    if omega_obs is not None:
        r = r + model.omega_weight * jnp.sum((state.omega - omega_obs) ** 2, axis=-1)
    return r


def _segment_misfit(model, inertia, q0, omega0, t, q_obs, omega_obs, weight):
    """Weighted misfit sum and final state of one segment, stepped ``substeps`` times per interval.

    Global step ``j`` lies in interval ``k = j // s`` at substep ``i = j % s``. With
    checkpointing the ``n_outer × n_inner`` steps are an outer scan over
    ``jax.checkpoint``-ed inner scans: the backward pass stores ``n_outer``
    carries and recomputes one chunk of ``n_inner`` steps at a time.
    """
    scheme, torque, args, s = model.scheme, model.torque, model.args, model.substeps
    dtype = q0.dtype

    def one_step(carry, j):
        inner, acc = carry
        k = j // s
        i = j - k * s
        dt = (t[k + 1] - t[k]) / s
        time = t[k] + i.astype(dtype) * dt
        inner = scheme.step(inner, time, dt, inertia, torque, args)
        state = scheme.state(inner)
        r = _misfit(model, state, q_obs[k + 1], None if omega_obs is None else omega_obs[k + 1])
        acc = acc + jnp.where(i == s - 1, weight[k + 1] * r, jnp.zeros((), dtype))
        return (inner, acc), None

    def chunk(carry, o):
        js = o * model.n_inner + jnp.arange(model.n_inner)
        carry, _ = jax.lax.scan(one_step, carry, js)
        return carry, None

    state0 = RotState(q0, omega0)
    acc0 = weight[0] * _misfit(model, state0, q_obs[0], None if omega_obs is None else omega_obs[0])
    carry = (scheme.init(state0, t[0], inertia, torque, args), acc0)
    if model.checkpoint:
        carry, _ = jax.lax.scan(jax.checkpoint(chunk), carry, jnp.arange(model.n_outer))
    else:
        carry, _ = jax.lax.scan(one_step, carry, jnp.arange(model.n_outer * model.n_inner))
    inner, acc = carry
    return acc, scheme.state(inner)


def unpack(params, model):
    """The tensor ``(3, 3)`` and the segments' start orientations ``(K, 4)`` of the parameters."""
    inertia = inertia_from_cholesky(params.chol, unit_trace=model.unit_trace)
    q_start = quat.multiply(quat.exp(params.dq), model.data.q_start)
    return inertia, q_start


def objective(params, model):
    """Mean weighted misfit over the observations, plus the continuity penalty between segments."""
    inertia, q_start = unpack(params, model)
    prepared = body_inertia(inertia)
    d = model.data
    misfit = jax.vmap(_segment_misfit, in_axes=(None, None, 0, 0, 0, 0, None if d.omega is None else 0, 0))
    sums, finals = misfit(model, prepared, q_start, params.omega, d.t, d.q, d.omega, d.weight)
    loss = jnp.sum(sums) / jnp.sum(d.weight)
    if q_start.shape[0] > 1:
        defect = orientation_misfit(finals.q[:-1], q_start[1:])
        mismatch = (finals.omega[:-1] - params.omega[1:]) * model.spacing
        defect = defect + jnp.sum(mismatch**2, axis=-1)
        loss = loss + model.continuity_weight * jnp.mean(defect)
    return loss


def single_shooting_loss(model, inertia, q0, omega0):
    """One-segment objective as a function of a raw tensor ``(3, 3)``, ``q0`` and ``omega0`` (for tests)."""
    d = model.data
    total, _ = _segment_misfit(
        model,
        body_inertia(inertia),
        q0,
        omega0,
        d.t[0],
        d.q[0],
        None if d.omega is None else d.omega[0],
        d.weight[0],
    )
    return total / jnp.sum(d.weight)


@eqx.filter_jit
def value_and_grad(params, model):
    return jax.value_and_grad(objective)(params, model)


def sample_states(scheme, torque, args, inertia, q0, omega0, t, substeps):
    """States ``q (n, 4)``, ``ω (n, 3)`` at the sample times ``t (n,)``, ``substeps`` steps per interval.

    ``inertia`` is a prepared `BodyInertia`. Repeating the last time pads ``t``:
    a step of length zero leaves the state as it is.
    """

    def interval(inner, k):
        dt = (t[k + 1] - t[k]) / substeps

        def one_step(inner, i):
            time = t[k] + i.astype(dt.dtype) * dt
            return scheme.step(inner, time, dt, inertia, torque, args), None

        inner, _ = jax.lax.scan(one_step, inner, jnp.arange(substeps))
        return inner, scheme.state(inner)

    state0 = RotState(q0, omega0)
    _, states = jax.lax.scan(
        interval, scheme.init(state0, t[0], inertia, torque, args), jnp.arange(t.shape[0] - 1)
    )
    return jnp.concatenate([q0[None], states.q]), jnp.concatenate([omega0[None], states.omega])


def predict(params, model):
    """Modelled states at the (padded) observation times of every segment: ``(K, P + 1, ...)``."""
    inertia, q_start = unpack(params, model)
    prepared = body_inertia(inertia)

    def segment(q0, omega0, t):
        return sample_states(model.scheme, model.torque, model.args, prepared, q0, omega0, t, model.substeps)

    return jax.vmap(segment)(q_start, params.omega, model.data.t)


@eqx.filter_jit
def residuals(params, model):
    """Residual vector whose sum of squares is `objective`, and the predicted states ``(K, P + 1, ...)``."""
    q, omega = predict(params, model)
    d = model.data
    scale = jnp.sqrt(d.weight / jnp.sum(d.weight))[..., None]
    parts = [(scale * signed_vector(q, d.q)).reshape(-1)]
    if d.omega is not None:
        parts.append((scale * jnp.sqrt(model.omega_weight) * (omega - d.omega)).reshape(-1))
    n_seg = q.shape[0]
    if n_seg > 1:
        _, q_start = unpack(params, model)
        joint = jnp.sqrt(model.continuity_weight / (n_seg - 1))
        parts.append((joint * signed_vector(q[:-1, -1], q_start[1:])).reshape(-1))
        parts.append((joint * model.spacing * (omega[:-1, -1] - params.omega[1:])).reshape(-1))
    return jnp.concatenate(parts), q, omega
