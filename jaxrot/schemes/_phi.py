"""The φ-functions of exponential integrators, finite in value and gradient from z = 0 to z → −∞.

``φ_0(z) = e^z`` and ``φ_k(z) = ∫_0^1 e^{(1−θ)z} θ^{k−1}/(k−1)! dθ`` for ``k ≥ 1``:
``φ_1(z) = (e^z − 1)/z``, ``φ_{k+1}(z) = (φ_k(z) − 1/k!)/z``, ``φ_k(0) = 1/k!``. The recurrence
cancels near ``z = 0``; there (``|z| ≤ 1``) the Taylor series of the highest ``φ_k`` is summed and
the lower ones follow from ``φ_{k−1} = 1/(k−1)! + z φ_k``, which loses nothing. Far out,
``e^z → 0`` and ``φ_k(z) → −1/((k−1)! z)``: finite at ``z = −1e8`` and ``−inf``. (M. Hochbruck and
A. Ostermann, "Exponential integrators", Acta Numerica 19, 209–286 (2010), section 2.)
"""

import math

import jax.numpy as jnp
import numpy as np


def _series_terms(dtype, k_max) -> int:
    """Terms of ``Σ zⁿ/(n + k_max)!`` that reach round-off for ``|z| ≤ 1``.

    The first term left out, ``1/(n + k_max)!``, is kept below ``eps/4`` of the smallest value the
    sum takes there, ``φ_{k_max}(−1) ≥ e^{−1}/k_max!``."""
    eps = float(jnp.finfo(dtype).eps)
    n = 0
    while 1 / math.factorial(n + k_max) >= eps / (4 * math.e * math.factorial(k_max)):
        n += 1
    return n


def phi_functions(z, k_max, xp=jnp):
    """``[φ_0(z), φ_1(z), …, φ_{k_max}(z)]``, each the shape of ``z``; ``z ≤ 0`` (a decay rate × −h).

    ``xp=numpy`` evaluates them without JAX: the tableau checks that run at import must not
    start a JAX backend (a program sets ``jax_num_cpu_devices`` and the like after importing us).

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot.schemes._phi import phi_functions
        >>> [round(float(p), 6) for p in phi_functions(jnp.array(0.0), 3)]
        [1.0, 1.0, 0.5, 0.166667]
        >>> [float(p) for p in phi_functions(jnp.array(-1e8), 2)]
        [0.0, 1e-08, 9.9999999e-09]
    """
    z = xp.asarray(z)
    if not xp.issubdtype(z.dtype, xp.floating):
        z = z.astype(jnp.result_type(float) if xp is jnp else np.float64)
    near = xp.abs(z) <= 1
    z_near = xp.where(near, z, 0)  # double where: each branch sees only arguments it is exact for
    z_far = xp.where(near, -1, z)
    series = xp.zeros_like(z)
    for n in reversed(range(_series_terms(z.dtype, k_max))):
        series = series * z_near + 1 / math.factorial(n + k_max)
    near_values = [series]
    for k in range(k_max, 0, -1):
        near_values.append(1 / math.factorial(k - 1) + z_near * near_values[-1])
    near_values.reverse()
    far_values = [xp.exp(z_far)]
    for k in range(1, k_max + 1):
        far_values.append((far_values[-1] - 1 / math.factorial(k - 1)) / z_far)
    return [xp.where(near, a, b) for a, b in zip(near_values, far_values, strict=True)]
