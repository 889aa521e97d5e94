"""MuJoCo XLA (MJX) beside jaxrot: the same bodies on both sides (benchmarks/mjx_peer.py's models).

Skipped without the ``mjx`` extra (``pip install -e ".[mjx]"``). The default set holds the cheap
checks (C MuJoCo compiles the benchmark's heavy top to jaxrot's physics; jaxrot's gradient at rest);
compiling MJX's step takes tens of seconds on 2 cores, so everything that runs MJX is in the slow set.
What MJX's integrators measure (their orders, the zero gradient at rest) is reported by the
benchmark (docs/mjx_cpu.json), not asserted here: it is MJX's behaviour, not a jaxrot promise.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat


pytest.importorskip("mujoco.mjx", reason='needs MuJoCo XLA: the "mjx" extra, pip install -e ".[mjx]"')
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import mjx_peer  # noqa: E402


@pytest.fixture(scope="module")
def problems():
    with jax.enable_x64(True):
        yield mjx_peer.problems(t_free=1.0, t_top=0.25)


def test_mujoco_compiles_the_heavy_top_to_jaxrots_physics(problems):
    """The benchmark's MuJoCo heavy top is jaxrot's scene: its body's compiled central moments are the
    eigenvalues of `central_inertia(pivot, mass, offset)`, its centre of mass sits at the offset, its
    mass is the scene's; the pivot tensor rebuilt from them is the scene's inertia."""
    import mujoco

    xml, state, inertia, torque, args, _ = problems["heavy_top"]
    model = mujoco.MjModel.from_xml_string(xml("rk4", 0.01))
    top = jaxrot.scenes.heavy_top()
    central = np.asarray(top.central_inertia())
    np.testing.assert_allclose(np.sort(model.body_inertia[1]), np.linalg.eigvalsh(central), rtol=1e-10)
    np.testing.assert_allclose(model.body_ipos[1], np.asarray(args["gravity"]["offset_body"]), atol=1e-14)
    assert model.body_mass[1] == pytest.approx(top.mass)
    # MuJoCo's principal frame (body_iquat) back to the body frame, then the parallel-axis theorem.
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.body_iquat[1])
    rot = rot.reshape(3, 3)
    central_mj = rot @ np.diag(model.body_inertia[1]) @ rot.T
    pivot = jaxrot.pivot_inertia(jnp.asarray(central_mj), top.mass, args["gravity"]["offset_body"])
    np.testing.assert_allclose(np.asarray(pivot), np.diag(np.asarray(inertia)), atol=1e-10)


@pytest.mark.parametrize("scheme", ["zhao", pytest.param("rkmk4", marks=pytest.mark.slow)])
def test_jaxrots_gradient_at_rest_is_finite_and_matches_finite_differences(problems, scheme):
    """The promise MJX's benchmark row is compared with: at ω = 0 jaxrot's gradient of a final-orientation
    loss w.r.t. the initial body rates is finite, non-zero and equals central finite differences and the
    exact derivative (to first order in ω the motion is q0 ⊗ exp(Tω), `quaternion.exp` of the rotation
    vector: every consistent scheme is exact there, so the tolerance is the finite differences'
    round-off, h = 1e-5: ~1e-9). One compiled program gives the values and the gradient."""
    with jax.enable_x64(True):
        _, state, inertia, *_ = problems["free_body"]
        n, dt = 20, 0.05

        def loss(w):
            return mjx_peer.loss_of_q(mjx_peer.jaxrot_final(scheme, inertia, state.q, dt, n)(w))

        value_and_grad = jax.jit(jax.value_and_grad(loss))
        w0, h = jnp.zeros(3), 1e-5
        g = np.asarray(value_and_grad(w0)[1])
        fd = np.array(
            [
                (value_and_grad(w0.at[i].set(h))[0] - value_and_grad(w0.at[i].set(-h))[0]) / (2 * h)
                for i in range(3)
            ]
        )
        exact = np.asarray(
            jax.grad(lambda w: mjx_peer.loss_of_q(quat.multiply(state.q, quat.exp(n * dt * w))))(w0)
        )
    assert np.all(np.isfinite(g)) and np.linalg.norm(g) > 0.1
    np.testing.assert_allclose(g, fd, atol=1e-8)
    np.testing.assert_allclose(g, exact, atol=1e-10)


@pytest.mark.slow
def test_mjx_and_jaxrot_agree_on_the_heavy_top_at_a_fine_step(problems):
    """Same physics: MJX's RK4 at dt = 2.5e-4 (|ω|dt ≈ 1.5e-3) over 0.25 s and jaxrot's reference agree
    to its second-order error (measured order 2 on the rotation: C (|ω|dt)² |ω|T with C of order 1,
    ~5e-6 rad): within 1e-4 rad, and the error falls by about 4 when the step is halved."""
    # MJX mixes a bool into float arithmetic (math.normalize_with_norm) and broadcasts ranks: the suite
    # refuses both (conftest.py), so MJX runs under jax's default promotion rules.
    with jax.enable_x64(True), jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        xml, state, inertia, torque, args, t_end = problems["heavy_top"]
        ref = jaxrot.reference_rollout(state, inertia, jnp.array([0.0, t_end]), torque=torque, args=args)
        omega_b = quat.rotate(quat.conjugate(state.q), state.omega)
        m = mjx_peer.mjx_model(xml("rk4", 0.01))
        d = mjx_peer.mjx_data(m, state.q, omega_b)
        run = mjx_peer.mjx_runner(m)
        errors = [mjx_peer.angle(run(mjx_peer.with_dt(m, t_end / n), d, n), ref.q[-1]) for n in (500, 1000)]
    assert errors[1] < 1e-4
    assert 2.5 < errors[0] / errors[1] < 6


@pytest.mark.slow
def test_mjx_finite_differences_at_rest_agree_with_jaxrots_gradient(problems):
    """At ω = 0 the two sides model the same motion: central finite differences of MJX's RK4 map equal
    jaxrot's gradient (1e-6: h = 1e-5 on a loss of order 1). MJX's own gradient there is reported by the
    benchmark, not asserted."""
    # MJX mixes a bool into float arithmetic (math.normalize_with_norm) and broadcasts ranks: the suite
    # refuses both (conftest.py), so MJX runs under jax's default promotion rules.
    with jax.enable_x64(True), jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        xml, state, inertia, *_ = problems["free_body"]
        n, dt = 20, 0.05
        final = mjx_peer.mjx_final(mjx_peer.mjx_model(xml("rk4", dt)), state.q, n)
        f = jax.jit(lambda w: mjx_peer.loss_of_q(final(w)))
        w0, h = jnp.zeros(3), 1e-5
        fd = np.array([(f(w0.at[i].set(h)) - f(w0.at[i].set(-h))) / (2 * h) for i in range(3)])
        g = jax.grad(
            lambda w: mjx_peer.loss_of_q(mjx_peer.jaxrot_final("rkmk4", inertia, state.q, dt, n)(w))
        )(w0)
    np.testing.assert_allclose(fd, np.asarray(g), atol=1e-6)
