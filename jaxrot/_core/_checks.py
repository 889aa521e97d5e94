"""The generic value checks every room may use: a clear ``ValueError`` before anything compiles.

Value checks run only on concrete arrays (`is_concrete`); on tracers they are skipped, never wrong.
Results that only exist at run time (a failed reference solve) go through `check_values`: one path
that raises now for concrete values and at run time for traced ones. The dtypes jaxrot computes in
(`SUPPORTED_DTYPES`) and the tolerance of a unit quaternion (`QUATERNION_NORM_TOL`) are set here.
The checks of a body's state, inertia and run are `jaxrot._validation`'s and `jaxrot._inertia`'s.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._concrete import is_concrete as is_concrete


QUATERNION_NORM_TOL = 1e-6
SUPPORTED_DTYPES = ("float32", "float64")


def check_values(x, failed, message, error=ValueError):
    """``x``, after checking that ``failed`` (a boolean array) holds nowhere.

    Concrete ``failed``: raises ``error(message)`` now. Traced: returns ``x`` with an
    ``eqx.error_if`` attached, which raises at run time; use the returned value, or
    the check is dropped with the unused branch.
    """
    if is_concrete(failed):
        if np.any(np.asarray(failed)):
            raise error(message)
        return x
    return eqx.error_if(x, failed, message)


def float_dtype(*xs):
    """The floating dtype results are computed in: that of the inputs, or JAX's default."""
    dtype = jnp.result_type(*xs)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return dtype


def declared_dtype(x, name):
    """The floating dtype that ``x`` declares, or None when it declares none.

    Python numbers and lists, weakly typed scalars and integer or boolean arrays
    declare none: they take the dtype of the other inputs. A complex array, or a
    floating one other than float32 and float64 (float16, bfloat16, ...), is a
    ``ValueError`` naming ``name``: it would otherwise fail later as a misleading
    "not unit" quaternion (float16 rounds |q| by ~5e-4).
    """
    dtype = getattr(x, "dtype", None)
    if dtype is None or getattr(x, "weak_type", False):
        return None
    dtype = np.dtype(dtype)
    if jnp.issubdtype(dtype, jnp.complexfloating) or (
        jnp.issubdtype(dtype, jnp.floating) and dtype.name not in SUPPORTED_DTYPES
    ):
        raise ValueError(
            f"`{name}` has dtype {dtype.name}; jaxrot computes in float32 or float64 only, and "
            "state.q and state.omega must share one of them (the inertia is cast to it). Cast it with "
            ".astype(jnp.float32) or .astype(jnp.float64)."
        )
    return dtype if jnp.issubdtype(dtype, jnp.floating) else None
