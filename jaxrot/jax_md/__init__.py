"""jaxrot inside jax_md: `nvt_langevin`, `nve`, `brownian` for ``jax_md.rigid_body`` simulations (optional).

``pip install "jaxrot[jax_md]"`` (jax_md needs a jax newer than some of jaxrot's supported ones:
Python 3.12 here), then swap one call::

    init_fn, apply_fn = jax_md.simulate.nvt_langevin(energy_fn, shift, dt, kT, gamma)   # before
    init_fn, apply_fn = jaxrot.jax_md.nvt_langevin(energy_fn, shift, dt, kT, gamma)     # after

The energy functions, shapes, neighbour lists, ``shift_fn`` and state types stay jax_md's, and
``jax_md.rigid_body.temperature`` / ``kinetic_energy`` read the state unchanged. The centres move as
jax_md moves them; the orientations by jaxrot's schemes (``"baoab"`` at a temperature, the exact free
rotor ``"splitting"`` or ``"no_squish"`` in NVE, ``"brownian_splitting"`` overdamped: `brownian`, which
jax_md's ``simulate.brownian`` cannot run on rigid bodies). Both thermostats take a rotational friction
per body axis (``rotational_friction=``), which jax_md's refuses. ``import jaxrot`` does not import this
module (nor jax_md): ``import jaxrot.jax_md``. Guide: docs/jax_md.md.
"""

from ._brownian import brownian as brownian
from ._convert import (
    angular_momentum as angular_momentum,
    body_torque as body_torque,
    conjugate_momentum as conjugate_momentum,
    from_rot_state as from_rot_state,
    to_rot_state as to_rot_state,
)
from ._simulate import nve as nve, nvt_langevin as nvt_langevin


__all__ = [
    "angular_momentum",
    "body_torque",
    "brownian",
    "conjugate_momentum",
    "from_rot_state",
    "nve",
    "nvt_langevin",
    "to_rot_state",
]
