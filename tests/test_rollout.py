"""rollout: saving, particle axes, per-particle inertia, jit/vmap/grad, t0."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, central_difference_grad, full_tensor, gravity_args, principal_state

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.scenes import gravity_torque


STATE = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))


def random_states(shape, seed=0):
    rng = np.random.default_rng(seed)
    q = quat.normalize(jnp.asarray(rng.normal(size=(*shape, 4))))
    return jaxrot.RotState(q, jnp.asarray(rng.normal(size=(*shape, 3))))


@pytest.mark.parametrize("n_steps, save_every", [(10, 1), (12, 3), (12, 4), (10, 10), (0, 1), (0, 5)])
def test_saved_shapes_and_times(n_steps, save_every):
    traj = jaxrot.rollout("zhao", STATE, MOMENTS, 0.1, n_steps, save_every=save_every, t0=2.0)
    n_saved = n_steps // save_every + 1
    assert traj.t.shape == (n_saved,)
    assert traj.q.shape == (n_saved, 4) and traj.omega.shape == (n_saved, 3)
    np.testing.assert_allclose(traj.t, 2.0 + 0.1 * save_every * np.arange(n_saved), atol=1e-14)
    np.testing.assert_array_equal(traj.q[0], STATE.q)
    np.testing.assert_allclose(traj.t[-1], 2.0 + 0.1 * n_steps, atol=1e-14)  # the final state is saved


@pytest.mark.parametrize(
    "n_steps, save_every, fix",
    [
        (10, 3, r"save_every=2 or 5 \(the divisors of 10 nearest 3\), or n_steps=9 or 12"),
        (7, 2, r"save_every=1 or 7 \(the divisors of 7 nearest 2\), or n_steps=6 or 8"),
        (3, 5, r"save_every=3 \(the divisors of 3 nearest 5\), or n_steps=5\."),
    ],
)
def test_save_every_that_does_not_divide_n_steps_is_rejected_before_compiling(n_steps, save_every, fix):
    traced = []

    def torque(t, q, omega, args):
        traced.append(t)
        return jnp.zeros(3)

    message = rf"`save_every` \(= {save_every}\) must divide `n_steps` \(= {n_steps}\).*{fix}"
    call = ("zhao", STATE, MOMENTS, 0.1, n_steps)
    with pytest.raises(ValueError, match=message):
        jaxrot.rollout(*call, torque=torque, save_every=save_every)
    with pytest.raises(ValueError, match=message):
        jaxrot.rollout(*call, torque=torque, save_every=save_every, chunk_steps=save_every)
    with pytest.raises(ValueError, match=message):
        jaxrot.rollout_chunks(*call, torque=torque, save_every=save_every, chunk_steps=save_every)
    assert not traced


def test_save_every_picks_the_same_states_as_saving_all():
    every = jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 12, torque=gravity_torque, args=gravity_args())
    sparse = jaxrot.rollout(
        "zhao", STATE, MOMENTS, 0.05, 12, torque=gravity_torque, args=gravity_args(), save_every=4
    )
    np.testing.assert_allclose(sparse.q, every.q[::4], atol=1e-15)
    np.testing.assert_allclose(sparse.omega, every.omega[::4], atol=1e-15)


def test_multiple_particle_axes_and_per_particle_full_tensors():
    states = random_states((2, 3))
    rng = np.random.default_rng(2)
    rots = quat.normalize(jnp.asarray(rng.normal(size=(2, 3, 4))))
    moments = jnp.asarray(rng.uniform(1.0, 2.0, size=(2, 3, 3)))
    tensors = jax.vmap(jax.vmap(full_tensor))(moments, rots)
    traj = jaxrot.rollout("zhao", states, tensors, 0.02, 20, save_every=10)
    assert traj.q.shape == (3, 2, 3, 4) and traj.omega.shape == (3, 2, 3, 3)
    one = jaxrot.rollout(
        "zhao", jaxrot.RotState(states.q[1, 2], states.omega[1, 2]), tensors[1, 2], 0.02, 20, save_every=10
    )
    np.testing.assert_allclose(traj.q[:, 1, 2], one.q, atol=1e-13)


def test_shared_inertia_broadcasts_over_particles():
    states = random_states((4,))
    shared = jaxrot.rollout("zhao", states, full_tensor(), 0.02, 10)
    per = jaxrot.rollout("zhao", states, jnp.broadcast_to(full_tensor(), (4, 3, 3)), 0.02, 10)
    np.testing.assert_allclose(shared.q, per.q, atol=1e-15)


def test_t0_shifts_a_time_dependent_torque():
    def torque(t, q, omega, args):
        return jnp.stack([jnp.sin(t), jnp.zeros_like(t), jnp.zeros_like(t)])

    late = jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 20, torque=torque, t0=1.0)

    def shifted(t, q, omega, args):
        return torque(t + 1.0, q, omega, args)

    early = jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 20, torque=shifted)
    np.testing.assert_allclose(late.q, early.q, atol=1e-14)


def test_works_under_jit_with_traced_inputs_and_no_check_touches_a_tracer():
    @jax.jit
    def run(state, inertia, dt):
        return jaxrot.rollout("zhao", state, inertia, dt, 20, torque=gravity_torque, args=gravity_args())

    eager = jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 20, torque=gravity_torque, args=gravity_args())
    jitted = run(STATE, MOMENTS, 0.05)
    np.testing.assert_allclose(jitted.q, eager.q, atol=1e-14)


def test_gradients_wrt_state_inertia_dt_and_torque_args_match_finite_differences():
    def loss(omega0, inertia, dt, weight_z):
        args = {"offset_body": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.array([0.0, 0.0, weight_z])}
        traj = jaxrot.rollout(
            "zhao", jaxrot.RotState(STATE.q, omega0), inertia, dt, 50, torque=gravity_torque, args=args
        )
        return jnp.sum(traj.q[-1] * jnp.array([0.2, -0.5, 0.7, 0.1])) + 0.1 * jnp.sum(traj.omega[-1] ** 2)

    # Strictly inside the triangle inequality (1, 2, 3 lies on it) so the stencil stays valid.
    primals = (STATE.omega, jnp.array([1.2, 2.0, 2.9]), jnp.asarray(0.02), jnp.asarray(-9.81))
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))(*primals)
    for argnum, grad in enumerate(grads):
        fd = central_difference_grad(loss, primals, argnum)
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-10)


def test_vmap_over_rollout_gives_per_particle_torque_parameters():
    weights = jnp.array([-9.81, -3.0, 0.0])

    def run(w):
        args = {"offset_body": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.stack([0.0 * w, 0.0 * w, w])}
        return jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 10, torque=gravity_torque, args=args).q

    batched = jax.vmap(run)(weights)
    for k, w in enumerate(weights):
        np.testing.assert_allclose(batched[k], run(w), atol=1e-14)


def test_scheme_object_and_name_are_interchangeable():
    by_name = jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 5)
    by_object = jaxrot.rollout(jaxrot.SCHEMES["zhao"], STATE, MOMENTS, 0.05, 5)
    np.testing.assert_array_equal(by_name.q, by_object.q)


def test_normalize_option_accepts_a_non_unit_quaternion():
    scaled = jaxrot.RotState(2.0 * STATE.q, STATE.omega)
    traj = jaxrot.rollout("zhao", scaled, MOMENTS, 0.05, 5, normalize=True)
    np.testing.assert_allclose(traj.q, jaxrot.rollout("zhao", STATE, MOMENTS, 0.05, 5).q, atol=1e-15)


# The two runs of the reliability issue that returned NaN without a word (0.5 and 1.5 rad per step).
BLOW_UPS = {
    "physical_body_at_half_a_radian": (
        jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.35, 0.2, 0.28])),
        jnp.array([1.0, 1.3, 2.2]),
        1.0,
    ),
    "flat_body": (
        jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([1.0, 5.0, 0.5])),
        jnp.array([0.2, 1.0, 1.1]),
        0.3,
    ),
}


@pytest.mark.parametrize("case", list(BLOW_UPS))
def test_an_eager_rollout_never_returns_nan_silently(case):
    """By default the saved states are checked: the error names the first non-finite saved state,
    the bodies affected, |ω|Δt and zhao's measured limit with a dt inside it; ``check_finite=False``
    returns the NaN; rollout_chunks checks each chunk."""
    state, inertia, dt = BLOW_UPS[case]
    speed = float(jnp.linalg.norm(state.omega))
    safe = jaxrot.stability.LIMITS["zhao"] / speed
    pattern = (
        r"returned a NaN or an infinity: first in saved state 1 \(t = 10000\), in 1 of 1 bodies"
        rf".*\|ω\|Δt was {speed * dt:.3g} rad.*up to 0\.3449 rad per step.*dt <= {safe:.3g}"
    )
    with pytest.raises(jaxrot.IntegrationError, match=pattern.replace("10000", f"{10000 * dt:g}")):
        jaxrot.rollout("zhao", state, inertia, dt, 10000, save_every=10000)
    unchecked = jaxrot.rollout("zhao", state, inertia, dt, 10000, save_every=10000, check_finite=False)
    assert not np.all(np.isfinite(unchecked.q[-1]))
    with pytest.raises(jaxrot.IntegrationError, match=r"rollout_chunks\(scheme='zhao'\).*saved state \d+"):
        list(jaxrot.rollout_chunks("zhao", state, inertia, dt, 10000, chunk_steps=5000, save_every=5000))


def test_the_finite_check_counts_bodies_and_spares_jit():
    """Two of three bodies blow up: "2 of 3". Under jit the result is traced and returned as it is
    (the documented way there is runtime_check=True)."""
    state, inertia, dt = BLOW_UPS["physical_body_at_half_a_radian"]
    omega = jnp.stack([state.omega, 0.01 * state.omega, state.omega])
    batch = jaxrot.RotState(jnp.broadcast_to(state.q, (3, 4)), omega)
    with pytest.raises(jaxrot.IntegrationError, match="in 2 of 3 bodies"):
        jaxrot.rollout("zhao", batch, inertia, dt, 10000, save_every=10000)
    run = jax.jit(lambda s: jaxrot.rollout("zhao", s, inertia, dt, 10000, save_every=10000).q[-1])
    assert int(jnp.sum(~jnp.all(jnp.isfinite(run(batch)), axis=-1))) == 2


def test_the_nonfinite_message_of_an_adaptive_solve():
    """`reference_rollout` checks its result the same way, with advice for an adaptive solve (no dt)."""
    from jaxrot._integrate._runtime_check import nonfinite_message

    q = jnp.zeros((3, 2, 4)).at[..., 0].set(1.0).at[2, 1, 0].set(jnp.nan)
    traj = jaxrot.Trajectory(jnp.array([0.0, 0.5, 1.0]), q, jnp.ones((3, 2, 3)))
    text = nonfinite_message(traj, None, "diffrax.Dopri8", "jaxrot.reference_rollout", advice="Check.")
    assert text == (
        "jaxrot.reference_rollout(scheme='diffrax.Dopri8') returned a NaN or an infinity: first in "
        "saved state 2 (t = 1), in 1 of 2 bodies. Check."
    )
    assert nonfinite_message(traj._replace(q=jnp.ones_like(q)), 0.1, "zhao") is None
