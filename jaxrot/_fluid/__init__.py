"""Bodies in a viscous fluid: the fluid's torques, the overdamped model and its schemes.

`_fluid` holds `Fluid` (a pytree of the friction, the flow and the temperature) and its checks,
`_perrin` Perrin's frictions of a spheroid, `_flow` the flow's rotation and strain and the torque
and angular velocity they give a body, `_overdamped` the inertia-free schemes and
`_overdamped_rollout` their time loop. The inertial schemes that integrate the friction without a
step limit are `jaxrot.schemes.ExpMidpoint` and `jaxrot.schemes.ExpRK4`.
"""
