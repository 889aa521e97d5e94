"""The tests' quaternion algebra in NumPy, for checks on already computed trajectories.

Each eager `jax.numpy` operation on a new shape compiles a small program (tens of them per test), so
the checks reimplement `jaxrot.quaternion`'s `multiply`, `conjugate`, `rotate`, `exp` and
`angle_between` here: scalar first, ``q`` maps body to world, in the arrays' own dtype.
"""

import numpy as np


def multiply(p, q):
    pw, px, py, pz = (p[..., k] for k in range(4))
    qw, qx, qy, qz = (q[..., k] for k in range(4))
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q):
    q = np.asarray(q)
    return np.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def rotate(q, v):
    q, v = np.asarray(q), np.asarray(v)
    w, u = q[..., :1], q[..., 1:]
    t = 2 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def exp(rotvec):
    """Rotation vector -> unit quaternion; ``sinc`` keeps it exact (and division-free) at zero angle."""
    theta = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    return np.concatenate([np.cos(theta / 2), 0.5 * np.sinc(theta / (2 * np.pi)) * rotvec], axis=-1)


def angle_between(q1, q2):
    """Geodesic angle (rad), sign-invariant."""
    d = multiply(conjugate(q1), q2)
    return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))
