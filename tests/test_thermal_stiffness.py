"""The thermal schemes at every stiffness: finite and right in law from ζΔt/I = 1e-8 to 1e8, in float32
and float64, at kT = 0 and kT > 0; their stability limits with a torque, on both sides of each edge.

The grid (`test_finite_and_right_in_law_from_1e_minus_8_to_1e8`, slow) holds the physics per step
fixed and moves the inertia alone: a rotational diffusion ``D Δt = kT Δt / ζ = 1e-3`` per step about
the stiffest axis, a dipole at ``μB/kT = 2`` (``K Δt/ζ = 2e-3``), inertia from ``ζΔt/(1e-8)`` to
``ζΔt/1e8``. At ``ζΔt/I = 1e8`` a thermal spin turns a body by ``√(kT/I) Δt ≈ 300`` rad per step
(textbook BAOAB's drift; the issue measured 74 rad and a NaN): the right law is the Brownian one.
Bodies start from the exact equilibrium (Boltzmann orientations, Maxwell spins) and must stay there:
per body axis ``⟨I_k ω_k²⟩ = kT`` (σ = √2 per body) and ``⟨cos θ⟩ = L(2)`` (σ = 0.43), within
``4σ/√N`` plus a bias bound of 0.02 (the schemes' weak errors at this step: ``BAOAB``'s kinetic bias
``O(K Δt²/I)`` and ``O(I/(ζΔt) · K Δt/ζ)``, ``ExpEuler``'s ``O(D Δt + K Δt/ζ)``, each ≤ 4e-3 here,
with a factor 5 for their unknown constants). A scheme that diffused ``ζΔt/(4I)`` times too fast
would bring ``⟨cos θ⟩`` to 0 within a step.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._equilibrium import dipole_orientations, langevin_function, maxwell_spins
from jaxrot._free_body._rotor import free_rotor, free_rotor_momentum


EZ = jnp.array([0.0, 0.0, 1.0])
X_DIPOLE = 2.0
SIGMA_COS = math.sqrt(
    1 - 2 * float(langevin_function(X_DIPOLE)) / X_DIPOLE - float(langevin_function(X_DIPOLE)) ** 2
)


def _field(dtype, strength):
    return {"field": {"moment_body": EZ.astype(dtype), "field": (strength * EZ).astype(dtype)}}


# --- the free rotor has no scale ----------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_free_rotor_is_the_same_at_every_scale_of_the_inertia(dtype):
    """The flow of ``ω`` depends on the moments' ratios only, and the rotor divides them by a power of
    two: moments scaled by ``2^±40`` (1e-12 and 1e12) give the very bits of the unscaled call (without
    the scaling, float32 gave NaN from ``I ~ 1e-4``: its modified moments' coefficients hold ``det⁻⁴``)."""
    q = quat.exp(jnp.array([0.3, -0.5, 0.7], dtype))
    omega = jnp.array([0.3, 2.0, 1.0], dtype)
    moments = jnp.array([3.4, 3.4, 0.4], dtype)
    # Each rotor compiled once for every call (the moments and the step are runtime values), not
    # dispatched one operation at a time: the scaled and unscaled calls run the same program.
    rotor, rotor_momentum = jax.jit(free_rotor), jax.jit(free_rotor_momentum)
    half = jnp.asarray(0.5, dtype)
    ref_q, ref_w = rotor(q, omega, moments, half)
    for scale in (2.0**-40, 2.0**-20, 2.0**40):
        q1, w1 = rotor(q, omega, moments * scale, half)
        np.testing.assert_array_equal(q1, ref_q)
        np.testing.assert_array_equal(w1, ref_w)
        q2, m2 = rotor_momentum(q, moments * scale * omega, moments * scale, half)
        assert np.all(np.isfinite(np.asarray(q2))) and np.all(np.isfinite(np.asarray(m2)))
    q3, w3 = rotor(q, omega, 1e-6 * moments, jnp.asarray(0.025, dtype))  # the guide's spheroid, not 2^k
    assert np.all(np.isfinite(np.asarray(q3))) and np.all(np.isfinite(np.asarray(w3)))


# --- the guide's spheroid (docs/fluid.md) at ζΔt/I ≈ 5e6 -----------------------------------------------


@jax.jit  # one program for the start (and one per kT), not one per eager operation
def _guide_start(fluid):
    q0 = quat.exp(jax.random.normal(jax.random.key(0), (16, 3), jnp.float32))
    return jaxrot.RotState(q0, fluid.angular_velocity(q0))


@pytest.mark.parametrize("kT", [0.0, 0.01])
@pytest.mark.parametrize("name", sorted(jaxrot.THERMAL_SCHEMES))
def test_the_guide_spheroid_in_float32(name, kT):
    """docs/fluid.md's spheroid (inertia 1e-6·(3.4, 3.4, 0.4), dt = 0.05, ζΔt/I 5e6 and 9e6) in float32:
    finite (``baoab`` returned NaN after one step); at kT = 0 it turns at the overdamped angular
    velocity from the second step on (within ``I/ζ``-sized terms, 1e-8 here, and 16 ulp of ``|ω| ≤ 0.6``;
    ``exp_euler``, order 1, that of the step's start, which lags by ``Δt |∇S| |S| ≤ 0.05·1·0.6``);
    at kT = 0.01 no step turns a body by more than the flow's turn (≤ 0.03 rad) plus six standard
    deviations of the Brownian one, ``√(2 kT Δt/ζ_min) = 3.7e-3`` (textbook BAOAB turned it by up to
    74 rad in float64)."""
    dtype = jnp.float32
    shear = jnp.zeros((3, 3), dtype).at[0, 1].set(1.0)
    fluid = jaxrot.Fluid.spheroid(4.0, 1.0, viscosity=1.0, velocity_gradient=shear, kT=kT)
    inertia = (1e-6 * jnp.array([3.4, 3.4, 0.4])).astype(dtype)
    state = _guide_start(fluid)
    key = jax.random.key(1) if kT > 0 else None
    traj = jaxrot.rollout(name, state, inertia, 0.05, 20, fluid=fluid, key=key)
    q, omega = np.asarray(traj.q), np.asarray(traj.omega)
    assert q.dtype == dtype and np.all(np.isfinite(q)) and np.all(np.isfinite(omega))
    if kT == 0:  # exp_euler (order 1) returns the slow velocity of the step's start: a lag Δt |∇S| |S|
        # one program, not one per operation
        expected = jax.jit(lambda f, q: f.angular_velocity(q))(fluid, traj.q[2:])
        lag = 0.0 if name == "baoab" else 0.05 * 1.0 * 0.6
        np.testing.assert_allclose(omega[2:], expected, atol=1e-8 + 16 * 1.2e-7 * 0.6 + lag)
    else:
        turn = jax.jit(quat.angle_between)(traj.q[1:], traj.q[:-1])
        brownian = math.sqrt(2 * kT * 0.05 / float(np.min(np.asarray(fluid.friction))))
        assert float(np.max(np.asarray(turn))) < 0.03 + 6 * brownian


# --- stability with a torque: both sides of each edge --------------------------------------------------

# (scheme, ζΔt/I, stiffness number inside, outside): exp_euler is stable while K Δt/ζ ≤ 2 at every
# ζΔt/I; baoab while K Δt/ζ ≤ 2 or K Δt²/I ≤ 4 (the linearised steps' spectral radii: 0.90 and 1.10
# at ζΔt/I = 1e4; baoab's 0.78 and 1.43 at ζΔt/I = 0.5, where K Δt²/I is the binding one).
EDGES = [
    ("exp_euler", 1e4, ("K dt/ζ", 1.9, 2.1)),
    ("baoab", 1e4, ("K dt/ζ", 1.9, 2.1)),
    ("baoab", 0.5, ("K dt²/I", 3.6, 4.4)),
]


@pytest.mark.parametrize("name, x, edge", EDGES)
def test_stability_with_a_torque_at_the_edge(name, x, edge):
    """A dipole at kT = 0, 1e-3 rad from its field, at rest (a sphere: ζΔt/I the same about every axis,
    no gyroscopic term; its stiffness ``K = μB``): inside the stated limit it settles (the angle falls
    below 1e-6 of its start in 300 steps: 0.9³⁰⁰ = 2e-14), outside it leaves (the angle grows past 10×
    its start: 1.1³⁰⁰ = 3e12 before the nonlinearity bounds it)."""
    dt, friction = 0.1, 1.0
    inertia = friction * dt / x
    label, inside, outside = edge
    q0 = quat.exp(jnp.array([1e-3, 0.0, 0.0]))
    for number, settles in ((inside, True), (outside, False)):
        stiffness = number * friction / dt if label == "K dt/ζ" else number * inertia / dt**2
        traj = jaxrot.rollout(
            name, jaxrot.RotState(q0, jnp.zeros(3)), inertia * jnp.ones(3), dt, 300,
            torque=jaxrot.torques.UniformField(), args=_field(jnp.float64, stiffness),
            fluid=jaxrot.Fluid(friction * jnp.ones(3)), save_every=300,
        )  # fmt: skip
        # cos θ = 1 − 2(x² + y²), the z component of the rotated body z, in NumPy (no eager programs)
        w, x, y, z = np.asarray(traj.q[-1])
        angle = float(np.arccos(np.clip(1 - 2 * (x * x + y * y), -1, 1)))
        if settles:
            assert angle < 1e-9, f"{name} at {label} = {number}: {angle:.2e}"
        else:
            assert angle > 1e-2, f"{name} at {label} = {number}: {angle:.2e}"


# --- the grid ----------------------------------------------------------------------------------------

N_GRID = 4000  # bodies per population: dipoles and free bodies
GRID = (1e-8, 1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6, 1e8)


def _grid_run(name, x, dtype, kT):
    """2N bodies (N dipoles at μB = 2, N free) of friction ζ₀ (1, 1.5, 2), ζ₀ = 1000, Δt = 1 (so
    ``kT Δt/ζ₀ = 1e-3``), inertia (1, 2, 3) ζ₀Δt/x: ζΔt/I = x (1, 0.75, 0.67). At kT > 0 from the
    equilibrium; at kT = 0 the dipoles from 1 rad off the field and every body at rest."""
    friction = 1000.0 * jnp.array([1.0, 1.5, 2.0])
    inertia = jnp.array([1.0, 2.0, 3.0]) * 1000.0 / x
    k1, k2, k3 = jax.random.split(jax.random.key(7), 3)
    if kT > 0:
        q = dipole_orientations(k1, N_GRID, X_DIPOLE)
        q = jnp.concatenate([q, quat.exp(jax.random.normal(k2, (N_GRID, 3)))])
        omega = maxwell_spins(k3, q, inertia, kT)
    else:
        tilted = jnp.tile(quat.exp(jnp.array([1.0, 0.0, 0.0])), (N_GRID, 1))
        q = jnp.concatenate([tilted, quat.exp(jax.random.normal(k2, (N_GRID, 3)))])
        omega = jnp.zeros((2 * N_GRID, 3))
    strength = jnp.concatenate([jnp.full(N_GRID, X_DIPOLE), jnp.zeros(N_GRID)])  # μB = 2 (kT = 1 or not)
    args = {"field": {"moment_body": EZ.astype(dtype),
                      "field": jaxrot.per_body((strength[:, None] * EZ[None]).astype(dtype))}}  # fmt: skip
    state = jaxrot.RotState(q.astype(dtype), omega.astype(dtype))
    return jaxrot.rollout(
        name, state, inertia.astype(dtype), 1.0, 40, torque=jaxrot.torques.UniformField(), args=args,
        fluid=jaxrot.Fluid(friction.astype(dtype), kT=kT), key=jax.random.key(8) if kT > 0 else None,
        save_every=10, check_finite=False,
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", sorted(jaxrot.THERMAL_SCHEMES))
def test_finite_and_right_in_law_from_1e_minus_8_to_1e8(name, dtype):
    """See the module docstring (kT = 1). At kT = 0: finite, and where ``ζΔt/I ≥ 1e2`` the dipoles follow
    the overdamped law ``tan(θ/2) = tan(θ₀/2) e^{−μB t/ζ}`` (ζ the friction about the turning axis,
    body x: 1000) within 2e-3 rad (Euler's global error ``(K Δt/ζ) θ/2 ≈ 1e-3`` and the inertial lag
    ``I/ζ · θ̇ ≤ 1e-2 · 2e-3``); the free bodies, at rest, stay there."""
    for x in GRID:
        warm = _grid_run(name, x, dtype, 1.0)
        assert warm.q.dtype == dtype
        assert bool(jnp.all(jnp.isfinite(warm.q)) & jnp.all(jnp.isfinite(warm.omega))), f"x = {x:g}"
        later = slice(1, None)
        inertia = np.array([1.0, 2.0, 3.0]) * 1000.0 / x
        spin = quat.rotate(quat.conjugate(warm.q[later]), warm.omega[later]).astype(jnp.float64)
        energy = np.asarray(jnp.mean(spin**2, axis=(0, 1))) * inertia
        np.testing.assert_array_less(np.abs(energy - 1), 4 * math.sqrt(2) / math.sqrt(2 * N_GRID) + 0.02,
                                     err_msg=f"{name} {dtype.__name__} ζΔt/I = {x:g}: ⟨I ω²⟩/kT")  # fmt: skip
        cos = float(jnp.mean(quat.rotate(warm.q[later, :N_GRID], EZ.astype(dtype))[..., 2]))
        assert abs(cos - float(langevin_function(X_DIPOLE))) < 4 * SIGMA_COS / math.sqrt(N_GRID) + 0.02, (
            f"{name} {dtype.__name__} ζΔt/I = {x:g}: ⟨cos θ⟩ = {cos:.4f}"
        )
        cold = _grid_run(name, x, dtype, 0.0)
        assert bool(jnp.all(jnp.isfinite(cold.q)) & jnp.all(jnp.isfinite(cold.omega))), f"x = {x:g}, kT = 0"
        eps = float(jnp.finfo(dtype).eps)
        still = quat.angle_between(cold.q[:, N_GRID:], cold.q[:1, N_GRID:])
        np.testing.assert_allclose(still, 0.0, atol=64 * eps)
        if x >= 1e2:
            cos = quat.rotate(cold.q[:, :N_GRID], EZ.astype(dtype))[..., 2]
            theta = np.asarray(jnp.arccos(jnp.clip(cos, -1, 1)))
            exact = 2 * np.arctan(np.tan(0.5) * np.exp(-X_DIPOLE * np.asarray(cold.t) / 1000.0))
            exact = np.broadcast_to(exact[:, None], theta.shape)
            np.testing.assert_allclose(theta, exact, atol=2e-3 + 1e3 * eps)
