"""`torques.Potential`: the torque of a one-body energy by differentiation, against the built-in models.

The built-ins' torques were written by hand (``r × F``, ``m × B``, the dipole field) and their energies
separately; ``Potential(their energy)`` must give the same torques, which pins the sign and the side
of the rotation: ``τ = −∂E(exp(δθ) ⊗ q)/∂δθ``, a world-frame rotation on the left.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat, torques
from jaxrot._particles import PARTICLES, split_per_body
from jaxrot.diagnostics import kinetic_energy


EPS = float(np.finfo(np.float64).eps)
RNG = np.random.default_rng(3)
N = 6
QS = quat.normalize(jnp.asarray(RNG.normal(size=(N, 4))))


def gravity_energy(t, q, p):
    return -jnp.dot(p["weight"], quat.rotate(q, p["offset_body"]))


def field_energy(t, q, p):
    return -jnp.dot(quat.rotate(q, p["moment_body"]), p["field"])


GRAVITY_ARGS = {
    "gravity": {
        "offset_body": jaxrot.per_body(jnp.asarray(RNG.normal(size=(N, 3)))),
        "weight": jnp.array([0.3, -0.4, -9.81]),
    }
}
FIELD_ARGS = {"field": {"moment_body": jnp.array([0.2, -1.0, 0.5]), "field": jnp.array([1.5, 0.3, -0.7])}}


def torques_of(model, qs, args):
    """Every body's torque as `rollout` computes it: vmapped over the named particle axis, each body
    with its row of the `per_body` parameters, compiled once."""
    values, axes = split_per_body(args, qs.shape[:-1])
    call = jax.vmap(lambda q, a: model(0.0, q, jnp.zeros(3), a), in_axes=(0, axes), axis_name=PARTICLES)
    return jax.jit(call)(qs, values)


@pytest.mark.parametrize(
    "builtin, potential, args",
    [
        (torques.Gravity(), torques.Potential(gravity_energy, key="gravity"), GRAVITY_ARGS),
        (torques.UniformField(), torques.Potential(field_energy, key="field"), FIELD_ARGS),
    ],
    ids=["gravity", "uniform_field"],
)
def test_torques_and_energies_match_the_builtin_models(builtin, potential, args):
    """Per body (shared and `per_body` parameters), torque to a few eps of its magnitude; energies equal."""
    expected = torques_of(builtin, QS, args)
    got = torques_of(potential, QS, args)
    np.testing.assert_allclose(got, expected, rtol=0, atol=16 * EPS * float(jnp.max(jnp.abs(expected))))
    np.testing.assert_allclose(potential.energy(0.0, QS, args), builtin.energy(0.0, QS, args), rtol=4 * EPS)
    assert potential.conservative and not potential.coupled


def test_dipole_interaction_torque_is_its_energy_differentiated_body_by_body():
    """Body i's energy: the dipoles' total with every other body held fixed. Its Potential torque is
    `DipoleInteraction`'s hand-written ``m_i × B(r_i)``, body by body; and each body's energy is the
    model's total energy."""
    model = torques.DipoleInteraction()
    positions = jnp.asarray(RNG.normal(size=(N, 3))) * 2
    args = {"dipoles": {"positions": positions, "moment_body": jnp.array([0.0, 0.3, 1.0]), "strength": 1.0}}

    def body_energy(t, q, p):
        return model.energy(t, p["q_all"].at[p["index"]].set(q), args)

    potential = torques.Potential(body_energy, key="frozen")
    frozen = {"frozen": {"q_all": QS, "index": jaxrot.per_body(jnp.arange(N))}}
    expected = torques_of(model, QS, args)
    got = torques_of(potential, QS, frozen)
    np.testing.assert_allclose(got, expected, rtol=0, atol=64 * EPS * float(jnp.max(jnp.abs(expected))))
    np.testing.assert_allclose(
        potential.energy(0.0, QS, frozen), N * model.energy(0.0, QS, args), rtol=16 * EPS
    )


@pytest.mark.parametrize(
    "q",
    [quat.identity(), jnp.array([0.0, 1.0, 0.0, 0.0]), jnp.array([0.0, 0.6, 0.0, 0.8]), QS[0] * 1.5],
    ids=["identity", "180_x", "180_generic", "non_unit"],
)
def test_finite_at_any_orientation_and_blind_to_the_norm(q):
    potential = torques.Potential(field_energy, key="field")
    torque = potential(0.0, q, jnp.zeros(3), FIELD_ARGS)
    unit = quat.normalize(q)
    expected = torques.UniformField()(0.0, unit, jnp.zeros(3), FIELD_ARGS)
    assert np.all(np.isfinite(torque))
    # A non-unit q scales rotate(q, ·) by |q|², in energy and torque alike; the rotation is what counts.
    np.testing.assert_allclose(torque, float(jnp.sum(q * q)) * expected, rtol=0, atol=16 * EPS)
    grads = jax.jit(jax.jacrev(lambda p: potential(0.0, q, jnp.zeros(3), p)))(FIELD_ARGS)
    assert all(np.all(np.isfinite(g)) for g in jax.tree_util.tree_leaves(grads))


def test_jacobian_with_respect_to_args_matches_the_builtin_model():
    """jit, vmap over bodies and grad of the torque with respect to its parameters (what fits use)."""

    def jacobian(model):
        values, axes = split_per_body(GRAVITY_ARGS, (N,))
        one = jax.jacrev(lambda a, q: model(0.0, q, jnp.zeros(3), a))
        return jax.jit(jax.vmap(one, in_axes=(axes, 0)))(values, QS)

    expected = jacobian(torques.Gravity())
    got = jacobian(torques.Potential(gravity_energy, key="gravity"))
    for g_p, g in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(expected), strict=True):
        np.testing.assert_allclose(g_p, g, rtol=0, atol=64 * EPS * 9.81)


@pytest.mark.slow  # two reverse-mode rollouts to compile (~15 s on 2 loaded cores)
def test_rollout_and_its_gradient_match_the_builtin_model():
    """Under rollout (jit, vmap over bodies, `per_body` rows) and grad with respect to args (fits)."""
    inertia = jnp.array([1.0, 2.0, 3.0])
    state = jaxrot.RotState.from_body(QS, jnp.asarray(RNG.normal(size=(N, 3))))

    def loss(model, args):
        traj = jaxrot.rollout("zhao", state, inertia, 0.01, 20, torque=model, args=args, save_every=20)
        return jnp.sum(traj.omega[-1] ** 2) + jnp.sum(traj.q[-1, :, 1:] ** 2)

    value, grad = jax.value_and_grad(loss, argnums=1)(torques.Gravity(), GRAVITY_ARGS)
    value_p, grad_p = jax.value_and_grad(loss, argnums=1)(
        torques.Potential(gravity_energy, key="gravity"), GRAVITY_ARGS
    )
    np.testing.assert_allclose(value_p, value, rtol=1e-13)
    for g_p, g in zip(jax.tree_util.tree_leaves(grad_p), jax.tree_util.tree_leaves(grad), strict=True):
        np.testing.assert_allclose(g_p, g, rtol=1e-11, atol=1e-13)


def test_energy_of_a_rollout_in_a_user_potential_stays_bounded():
    """A potential no built-in model has (a nematic pull on body z plus a tilt on body x), under the
    symplectic `no_squish` splitting: the energy error of a second-order symplectic scheme oscillates
    without drift at O(dt²). Measured 7.3e-5 relative at dt = 0.01 (and 2.9e-4 at 0.02: dt², ratio 4.0);
    a torque of the wrong sign or side breaks this by O(1)."""

    def nematic(t, q, p):
        u = quat.rotate(q, jnp.array([0.0, 0, 1]))
        return -p["k"] * jnp.dot(p["n"], u) ** 2 + 0.3 * jnp.dot(
            p["n2"], quat.rotate(q, jnp.array([1.0, 0, 0]))
        )

    model = torques.Potential(nematic)
    args = {"k": 1.5, "n": jnp.array([1.0, 0, 0]), "n2": jnp.array([0.0, 0.6, 0.8])}
    inertia = jnp.array([1.0, 2.0, 3.0])
    state = jaxrot.RotState.from_body(quat.exp(jnp.array([0.3, -0.2, 0.5])), jnp.array([0.5, 1.5, -0.7]))
    n_steps = 2000
    traj = jaxrot.rollout("no_squish", state, inertia, 0.01, n_steps, torque=model, args=args)
    energy = kinetic_energy(traj.q, traj.omega, inertia) + jax.vmap(
        lambda q: model.energy(0.0, q[None], args)
    )(traj.q)
    error = np.abs(np.asarray(energy - energy[0])) / float(energy[0])
    assert error.max() < 2e-4
    assert error[n_steps // 2 :].max() < 1.5 * error[: n_steps // 2].max()  # no secular drift


def test_energy_must_be_callable():
    with pytest.raises(ValueError, match="`energy` must be a callable"):
        torques.Potential(1.0)
