"""The model and the objective: rollouts from the fitted start states, misfits to the observations.

`_objective` is the mean weighted misfit (with the continuity penalty of multiple
shooting), differentiated by `_value_and_grad`; `_residuals` is the same objective
as a vector whose sum of squares it is, for the Gauss–Newton whitening and
least-squares solvers, with the predicted states.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._inertia import body_inertia
from .._state import RotState
from ._parameterisation import inertia_from_cholesky


def _orientation_misfit(q, q_obs):
    """``4 |v|²`` of ``q_obs* ⊗ q = (w, v)``: ``4 sin²(θ/2) ≈ θ²``, sign invariant, smooth, finite gradient.

    For unit quaternions this is ``4 (1 − (q·q_obs)²)``, but computed without that
    cancellation: ``1 − c²`` is a difference of O(1) numbers, so it is known only to
    ~eps absolute (it came out −5e-16 at a perfect fit, and could not resolve misfits
    below ~√eps rad: 3e-4 rad in float32). Each component of ``v`` is a short sum of
    products, correct to ~eps absolute, so ``4 |v|²`` is never negative and resolves
    angles down to ~eps; a ``|q|`` off 1 by round-off scales it instead of shifting it.
    """
    v = quat.multiply(quat.conjugate(q_obs), q)[..., 1:]
    return 4 * jnp.sum(v * v, axis=-1)


def _misfit(problem, state, q_obs, omega_obs):
    r = _orientation_misfit(state.q, q_obs)
    if omega_obs is not None:
        r = r + problem.omega_weight * jnp.sum((state.omega - omega_obs) ** 2, axis=-1)
    return r


def _segment_misfit(problem, inertia, q0, omega0, t, q_obs, omega_obs, weight):
    """Weighted misfit sum and final state of one segment, stepped ``substeps`` times per interval.

    Global step ``j`` lies in interval ``k = j // s`` at substep ``i = j % s``. With
    checkpointing the ``n_outer × n_inner`` steps are an outer scan over
    ``jax.checkpoint``-ed inner scans: the backward pass stores ``n_outer``
    carries and recomputes one chunk of ``n_inner`` steps at a time.
    """
    scheme, torque, args, s = problem.scheme, problem.torque, problem.args, problem.substeps
    dtype = q0.dtype

    def one_step(carry, j):
        inner, acc = carry
        k = j // s
        i = j - k * s
        dt = (t[k + 1] - t[k]) / s
        time = t[k] + i.astype(dtype) * dt
        inner = scheme.step(inner, time, dt, inertia, torque, args)
        state = scheme.state(inner)
        r = _misfit(problem, state, q_obs[k + 1], None if omega_obs is None else omega_obs[k + 1])
        acc = acc + jnp.where(i == s - 1, weight[k + 1] * r, jnp.zeros((), dtype))
        return (inner, acc), None

    def chunk(carry, o):
        js = o * problem.n_inner + jnp.arange(problem.n_inner)
        carry, _ = jax.lax.scan(one_step, carry, js)
        return carry, None

    state0 = RotState(q0, omega0)
    acc0 = weight[0] * _misfit(problem, state0, q_obs[0], None if omega_obs is None else omega_obs[0])
    carry = (scheme.init(state0, t[0], inertia, torque, args), acc0)
    if problem.checkpoint:
        carry, _ = jax.lax.scan(jax.checkpoint(chunk), carry, jnp.arange(problem.n_outer))
    else:
        carry, _ = jax.lax.scan(one_step, carry, jnp.arange(problem.n_outer * problem.n_inner))
    inner, acc = carry
    return acc, scheme.state(inner)


def _unpack(params, problem):
    inertia = inertia_from_cholesky(params.chol, unit_trace=problem.unit_trace)
    q_start = quat.multiply(quat.exp(params.dq), problem.data.q_start)
    return inertia, q_start


def _objective(params, problem):
    """Mean weighted misfit over the observations, plus the continuity penalty between segments."""
    inertia, q_start = _unpack(params, problem)
    prepared = body_inertia(inertia)
    d = problem.data
    misfit = jax.vmap(_segment_misfit, in_axes=(None, None, 0, 0, 0, 0, None if d.omega is None else 0, 0))
    sums, finals = misfit(problem, prepared, q_start, params.omega, d.t, d.q, d.omega, d.weight)
    loss = jnp.sum(sums) / jnp.sum(d.weight)
    if q_start.shape[0] > 1:
        defect = _orientation_misfit(finals.q[:-1], q_start[1:])
        mismatch = (finals.omega[:-1] - params.omega[1:]) * problem.spacing
        defect = defect + jnp.sum(mismatch**2, axis=-1)
        loss = loss + problem.continuity_weight * jnp.mean(defect)
    return loss


def _single_shooting_loss(problem, inertia, q0, omega0):
    """One-segment objective as a function of a raw tensor ``(3, 3)``, ``q0`` and ``omega0`` (for tests)."""
    d = problem.data
    total, _ = _segment_misfit(
        problem,
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
def _value_and_grad(params, problem):
    return jax.value_and_grad(_objective)(params, problem)


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


def _predict(params, problem):
    """Modelled states at the (padded) observation times of every segment: ``(K, P + 1, ...)``."""
    inertia, q_start = _unpack(params, problem)
    prepared = body_inertia(inertia)

    def segment(q0, omega0, t):
        return sample_states(
            problem.scheme, problem.torque, problem.args, prepared, q0, omega0, t, problem.substeps
        )

    return jax.vmap(segment)(q_start, params.omega, problem.data.t)


def signed_vector(q, q_ref):
    """``2 v sign(w)`` of ``q_ref* ⊗ q = (w, v)``: its squared norm is `_orientation_misfit`."""
    d = quat.multiply(quat.conjugate(q_ref), q)
    return 2 * jnp.where(d[..., :1] < 0, -d[..., 1:], d[..., 1:])


@eqx.filter_jit
def _residuals(params, problem):
    """Residual vector whose sum of squares is `_objective`, and the predicted states ``(K, P + 1, ...)``."""
    q, omega = _predict(params, problem)
    d = problem.data
    scale = jnp.sqrt(d.weight / jnp.sum(d.weight))[..., None]
    parts = [(scale * signed_vector(q, d.q)).reshape(-1)]
    if d.omega is not None:
        parts.append((scale * jnp.sqrt(problem.omega_weight) * (omega - d.omega)).reshape(-1))
    n_seg = q.shape[0]
    if n_seg > 1:
        _, q_start = _unpack(params, problem)
        joint = jnp.sqrt(problem.continuity_weight / (n_seg - 1))
        parts.append((joint * signed_vector(q[:-1, -1], q_start[1:])).reshape(-1))
        parts.append((joint * problem.spacing * (omega[:-1, -1] - params.omega[1:])).reshape(-1))
    return jnp.concatenate(parts), q, omega
