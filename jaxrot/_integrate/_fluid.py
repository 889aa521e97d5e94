"""A rollout's ``fluid=``: the scheme that integrates its friction and the per-body values it reads."""

import math

from .._fluid._fluid import check_fluid
from .._inertia import is_diagonal_form
from ..schemes import FLUID_SCHEMES
from ..schemes._exponential import FluidArgs
from ._thermal_bind import bind_thermal, is_langevin, without_temperature


def _capable():
    return ", ".join(f"{name!r} (order {scheme.order})" for name, scheme in FLUID_SCHEMES.items())


def bind_fluid(scheme, fluid, key, batch_shape, dtype, inertia, args, args_axes, drive):
    """``(scheme, args, args_axes)`` of a rollout in ``fluid``: the scheme's fluid form, its args a
    `FluidArgs` of the torque's args and the flattened per-body `jaxrot.Fluid` values.

    Raises ValueError, before anything compiles, for a scheme that cannot integrate the friction
    without a step limit (every explicit scheme of `jaxrot.SCHEMES`: their steps would be limited to
    about ζΔt/I < 2, and a splitting's exact friction step loses the torque's time scale as
    ζΔt/I → ∞), a full inertia tensor, or a drive.
    """
    in_fluid = getattr(scheme, "in_fluid", None)
    if in_fluid is None and not is_langevin(scheme):
        raise ValueError(
            f"scheme {scheme.name!r} cannot integrate a fluid's friction (`fluid=`): its explicit steps are "
            f"stable only while ζΔt/I stays below about 2. Use {_capable()}, which take the friction's "
            "relaxation exactly at any step; or pass the fluid's torque as a plain torque callable, "
            "torque=lambda t, q, omega, args: fluid.torque(q, omega), with a step inside that limit."
        )
    if not is_diagonal_form(inertia):
        raise ValueError(
            "`inertia` must be principal moments (..., 3) about the body axes of the fluid's friction for a "
            "rollout with `fluid`: a full (3, 3) tensor, whose principal axes differ from the friction's, "
            "is not supported. Express the body in its principal frame."
        )
    if drive is not None:
        raise ValueError("`drive` and `fluid` cannot be combined: pass one of them.")
    values, axes = check_fluid(fluid, batch_shape, dtype, key)
    if is_langevin(scheme):  # at a temperature (`jaxrot._thermal`): the noise's keys travel with args
        return bind_thermal(scheme, values, axes, args, args_axes, key, math.prod(batch_shape))
    values = without_temperature(values, scheme.name, key)
    return in_fluid(), FluidArgs(args, values), FluidArgs(args_axes, axes)
