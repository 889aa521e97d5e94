"""What both fits' starts are made of: angular velocities by finite differences and a linear inertia estimate.

The angular-momentum balance is linear in the tensor and the initial momentum
(`linear_estimate`); solved by least squares it lands within ~0.3 % of the
tensor, inside the basin of the nonlinear fit, so no multi-start is needed.
Each stack's ``_start`` module builds its start from these.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat


@jax.jit
def _log_of_difference(p, q):
    """``log(p ⊗ q*)``, compiled once per shape: eagerly, its ~20 operations took 50 ms of a fit's start."""
    return quat.log(quat.multiply(p, quat.conjugate(q)))


def _log_difference_np(p, q):
    return np.asarray(_log_of_difference(jnp.asarray(p), jnp.asarray(q)))


_rotated = jax.jit(quat.rotate)  # as `_log_of_difference`: eagerly, ~30 single-op programs
_multiplied = jax.jit(quat.multiply)


def rotate_np(q, v):
    """`jaxrot.quaternion.rotate` of NumPy arrays, compiled once per shape, as a NumPy array."""
    return np.asarray(_rotated(jnp.asarray(q), jnp.asarray(v)))


def multiply_np(p, q):
    """`jaxrot.quaternion.multiply` of NumPy arrays, compiled once per shape, as a NumPy array."""
    return np.asarray(_multiplied(jnp.asarray(p), jnp.asarray(q)))


@jax.jit(static_argnums=0)
def _torques_at(torque, t, q, omega, args):
    return jax.vmap(lambda tk, qk, wk: torque(tk, qk, wk, args))(t, q, omega)


def estimate_omega(t, q):
    """World angular velocity ``(n, 3)`` from orientations ``(n, 4)`` by three-point differences.

    ``φ(τ) = log(q(t_k + τ) ⊗ q(t_k)*)`` has ``φ'(0) = ω(t_k)`` (world frame); its
    derivative is taken from the neighbours (central inside, one-sided at the
    ends), second order also for uneven spacing. Needs ``n ≥ 3``.
    """
    t = np.asarray(t, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    n = t.shape[0]
    omega = np.empty((n, 3))
    # interior: points at -a, 0, +b
    a = (t[1:-1] - t[:-2])[:, None]
    b = (t[2:] - t[1:-1])[:, None]
    # Every difference in one call (one dispatch instead of six, a few ms of `identify`'s start):
    # the interior's forward and backward ones, then each end's two.
    ends = ((0, (1, 2)), (n - 1, (n - 2, n - 3)))
    end_pairs = [(k_other, k) for k, others in ends for k_other in others]  # (later, earlier) rows
    later = np.concatenate([q[2:], q[:-2], q[[a for a, _ in end_pairs]]])
    earlier = np.concatenate([q[1:-1], q[1:-1], q[[b for _, b in end_pairs]]])
    logs = _log_difference_np(later, earlier)
    fwd, bwd, at_ends = logs[: n - 2], logs[n - 2 : 2 * (n - 2)], logs[2 * (n - 2) :]
    omega[1:-1] = (a**2 * fwd - b**2 * bwd) / (a * b * (a + b))
    # ends: points at 0, h1, h2 (h1, h2 of either sign)
    for e, (k, (k1, k2)) in enumerate(ends):
        h1, h2 = t[k1] - t[k], t[k2] - t[k]
        p1, p2 = at_ends[2 * e], at_ends[2 * e + 1]
        omega[k] = (p1 * h2**2 - p2 * h1**2) / (h1 * h2 * (h2 - h1))
    return omega


def linear_estimate(t, q, omega, torque, args, dtype, extra_impulse=None):
    """Inertia from the angular-momentum balance ``R_k I ω_b,k − L₀ = ∫₀^{t_k} τ dt``, linear in ``(I, L₀)``.

    Torque-free the system is homogeneous: ``(I, L₀)`` is its smallest right
    singular vector, normalised to ``tr I = 1``. With a torque the impulse on the
    right fixes the scale (least squares). Noisy ``ω`` makes this a rough but
    unbiased-enough start; the gradient fit then refines it. ``extra_impulse`` ``(n, 3)``:
    a known impulse from ``t[0]`` to each sample (a control's) added to the torque's.
    """
    rot = np.asarray(quat.to_matrix(jnp.asarray(q)))
    w_b = np.einsum("kji,kj->ki", rot, omega)  # R_kᵀ ω_k
    zero = np.zeros(len(t))
    wx, wy, wz = w_b[:, 0], w_b[:, 1], w_b[:, 2]
    # I ω_b as a linear map of (Ixx, Iyy, Izz, Ixy, Ixz, Iyz)
    a = np.stack(
        [
            np.stack([wx, zero, zero, wy, wz, zero], axis=-1),
            np.stack([zero, wy, zero, wx, zero, wz], axis=-1),
            np.stack([zero, zero, wz, zero, wx, wy], axis=-1),
        ],
        axis=1,
    )  # (n, 3, 6)
    rows = np.concatenate([rot @ a, np.broadcast_to(-np.eye(3), (len(t), 3, 3))], axis=-1).reshape(-1, 9)
    scale_free = torque is None and extra_impulse is None
    if scale_free:
        _, _, vt = np.linalg.svd(rows, full_matrices=False)
        x = vt[-1]
    else:
        impulse = np.zeros((len(t), 3)) if extra_impulse is None else np.asarray(extra_impulse, np.float64)
        if torque is not None:
            tau = _torques_at(
                torque, jnp.asarray(t, dtype), jnp.asarray(q, dtype), jnp.asarray(omega, dtype), args
            )
            tau = np.asarray(tau, dtype=np.float64)
            impulse = impulse + np.concatenate(
                [np.zeros((1, 3)), np.cumsum(0.5 * (tau[1:] + tau[:-1]) * np.diff(t)[:, None], 0)]
            )
        x, *_ = np.linalg.lstsq(rows, impulse.reshape(-1), rcond=None)
    xx, yy, zz, xy, xz, yz = x[:6]
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    momentum = x[6:]
    if scale_free:
        trace = np.trace(inertia)
        if trace == 0:
            return np.eye(3) / 3, None
        inertia, momentum = inertia / trace, momentum / trace
    return inertia, momentum
