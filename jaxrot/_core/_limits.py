"""The measured stability limits that `jaxrot.stability` publishes and `jaxrot.rollout` quotes."""

# The largest |ω|Δt (rad) with an error per step <= 1e-3 rad on the default body, float64 (float32
# measures the same), from `max_stable_rotation_per_step`; tests/test_stability.py checks each. The
# splittings are absent: torque-free they are their exact-to-round-off rotor at any |ω|Δt up to 10.
# `jaxrot.rollout` quotes them when a run returns a NaN.
LIMITS = {
    "zhao": 0.3449,
    "rozmanov": 0.3253,
    "euler": 0.09072,
    "no_squish": 0.242,
    "rkmk4": 1.075,
    "rkmk_dopri5": 1.396,
    "rkmk_dopri8": 2.541,
}

# The schemes of a fluid at a temperature have no free-body limit (their rotation is exact or
# relaxed exactly at any ζΔt/I); what bounds their step is the applied torque's stiffness K = |∂τ/∂θ|
# (torque per radian), from the linearised step about a minimum (jaxrot.schemes.ExpEuler, BAOAB;
# tests/test_stability.py checks both sides of each edge). `jaxrot.rollout` quotes them.
TORQUE_LIMITS = {
    "exp_euler": "stable for a torque of stiffness K = |∂τ/∂θ| while K·dt/ζ <= 2 (ζ the smallest friction)",
    "baoab": "stable for a torque of stiffness K = |∂τ/∂θ| while K·dt/ζ <= 2 (ζ the smallest friction) "
    "or K·dt²/I <= 4 (I the smallest moment)",
}
