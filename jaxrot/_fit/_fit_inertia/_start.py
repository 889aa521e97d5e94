"""`fit_inertia`'s start: the parameters (`_Params`) Gauss–Newton starts from.

The tensor from the linear angular-momentum balance (`_initial.linear_estimate`) or
``inertia0``, ``ω0`` from the balance's momentum, the differenced ``ω`` or ``omega0``.
"""

import jax.numpy as jnp
import numpy as np

from ... import quaternion as quat
from ..._validation import check_finite_array
from .._initial import linear_estimate
from .._parameterisation import _Params, cholesky_from_inertia, inertia_from_cholesky


def starting_point(settings, *, torque, args, unit_trace, segments, inertia0, omega0) -> _Params:
    """The parameters the optimiser starts from, for the `Settings` and `fit_inertia`'s options.

    The tensor is ``inertia0`` or the linear estimate; ``ω0`` is ``omega0``, or (one
    segment) ``R₀ I⁻¹ R₀ᵀ L₀`` from the estimate's momentum, else the differenced
    ``ω`` at each segment start; the orientation offsets are zero.
    """
    dtype, bounds, omega_est = settings.dtype, settings.bounds, settings.omega_estimate

    momentum = None
    if inertia0 is None:
        start, momentum = linear_estimate(settings.t, settings.q, omega_est, torque, args, dtype)
    else:
        start = check_finite_array(inertia0, "inertia0", (3, 3), "(3, 3) tensor")
    chol = cholesky_from_inertia(start)
    if unit_trace:
        # Only the shape of S is determined: L₀₀ stays at its start value (it is not a fit parameter).
        chol = chol / chol[0]
    start_omega = np.array(omega_est[bounds[:-1]])
    if momentum is not None and omega0 is None and segments == 1:
        # ω0 = R₀ I⁻¹ R₀ᵀ L₀ from the momentum fitted to all samples: far better than differencing.
        start_tensor = np.asarray(inertia_from_cholesky(jnp.asarray(chol), unit_trace=unit_trace))
        rot0 = np.asarray(quat.to_matrix(jnp.asarray(settings.q[0])))
        candidate = rot0 @ np.linalg.solve(start_tensor, rot0.T @ momentum)
        if np.all(np.isfinite(candidate)):
            start_omega[0] = candidate
    if omega0 is not None:
        omega0 = check_finite_array(omega0, "omega0", (3,), "world-frame (3,) vector")
        start_omega[0] = omega0
    return _Params(
        chol=jnp.asarray(chol, dtype),
        dq=jnp.zeros((segments, 3), dtype),
        omega=jnp.asarray(start_omega, dtype),
    )
