"""Built-in scenes with every scheme, their invariants, coupled torques, "pay only for what is declared"."""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import contract_params, refuses_velocity_torques, scheme_params

import jaxrot
from jaxrot import quaternion as quat, torques
from jaxrot.comparison import compare
from jaxrot.diagnostics import angular_momentum, kinetic_energy
from jaxrot.scenes import SCENES, dipole_cloud, tumbling_cloud


N_STEPS = 200


# Scenes whose torque depends on ω, which the RKN splittings refuse by design.
VELOCITY_DEPENDENT = {"viscous_drag"}


def run_unless_refused(scheme, name, scene, **kwargs):
    """`run`, or None after checking that ``scheme`` refuses the ω-dependent torque of scene ``name``."""
    if name in VELOCITY_DEPENDENT and refuses_velocity_torques(scheme):
        with pytest.raises(ValueError, match="depends on the angular velocity"):
            run(scheme, scene, **kwargs)
        return None
    return run(scheme, scene, **kwargs)


def small(name):
    """The scene, with clouds cut down so that every scheme compiles and runs in about a second."""
    if name == "tumbling_cloud":
        return tumbling_cloud(n=8)
    if name == "dipole_cloud":
        return dipole_cloud(n_side=3)
    return SCENES[name]()


def run(scheme, scene, n_steps=N_STEPS, dt=None):
    dt = scene.dt if dt is None else dt
    return jaxrot.rollout(
        scheme,
        scene.state,
        scene.inertia,
        dt,
        n_steps,
        torque=scene.torque,
        args=scene.args,
        drive=scene.drive,
    )


def relative_energy_error(scene, traj):
    energy = scene.energy(0.0, traj.q, traj.omega)
    return float(jnp.max(jnp.abs(energy - energy[0])) / jnp.abs(energy[0]))


# Largest relative energy error over N_STEPS at the scene's dt. Measured worst cases: 1.5e-4 for a
# second-order scheme (dipole cloud, rozmanov), 0.12 for first-order Euler (dipole cloud); the
# bounds leave a factor of 2.5–7. The splitting scheme is exact for torque-free scenes (1.3e-14).
ENERGY_BOUND = {"euler": 0.3}
ENERGY_BOUND_SECOND_ORDER = 1e-3
CONSERVATIVE = ["free_top", "heavy_top", "lagrange_top", "dipole_field", "dipole_cloud", "tumbling_cloud"]


@pytest.mark.parametrize("scheme", contract_params())
@pytest.mark.parametrize("name", list(SCENES))
def test_every_scene_runs_with_every_scheme_and_keeps_its_energy(name, scheme):
    scene = small(name)
    traj = run_unless_refused(scheme, name, scene)
    if traj is None:
        return
    assert bool(jnp.all(jnp.isfinite(traj.q)) & jnp.all(jnp.isfinite(traj.omega)))
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(traj.q, axis=-1) - 1))) < 1e-12
    if name in CONSERVATIVE:
        bound = ENERGY_BOUND.get(scheme, ENERGY_BOUND_SECOND_ORDER)
        if scheme == "splitting" and scene.torque is None:
            bound = 1e-12
        assert relative_energy_error(scene, traj) < bound
    else:
        assert scene.energy(0.0, traj.q, traj.omega) is None


@pytest.mark.parametrize("scheme", scheme_params(["zhao", "no_squish", "splitting"]))
def test_free_bodies_keep_their_world_angular_momentum(scheme):
    for scene in (small("free_top"), small("tumbling_cloud")):
        traj = run(scheme, scene)
        momentum = angular_momentum(traj.q, traj.omega, scene.inertia)
        drift = jnp.max(
            jnp.linalg.norm(momentum - momentum[:1], axis=-1) / jnp.linalg.norm(momentum[:1], axis=-1)
        )
        # NO_SQUISH and the splitting scheme conserve it exactly (round-off); Zhao to its accuracy.
        assert float(drift) < (1e-3 if scheme == "zhao" else 1e-12)


def test_lagrange_top_keeps_vertical_and_axial_momentum():
    scene = small("lagrange_top")
    traj = run("no_squish", scene, n_steps=1000)
    momentum = angular_momentum(traj.q, traj.omega, scene.inertia)
    axis = quat.rotate(traj.q, jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0]), traj.omega.shape))
    vertical, axial = momentum[:, 2], jnp.sum(momentum * axis, axis=-1)
    # Gravity's torque is horizontal and NO_SQUISH's kicks and rotors keep world L: exact to round-off.
    assert float(jnp.max(jnp.abs(vertical - vertical[0]))) < 1e-12 * float(jnp.abs(axial[0]))
    # The axial component is exact for the ODE; the R1/R2 sub-rotations of the splitting move it at O(dt²).
    assert float(jnp.max(jnp.abs(axial - axial[0]))) < 1e-6 * float(jnp.abs(axial[0]))


def test_dipole_in_a_uniform_field_keeps_momentum_along_the_field():
    scene = small("dipole_field")
    traj = run("no_squish", scene, n_steps=1000)
    along = angular_momentum(traj.q, traj.omega, scene.inertia) @ scene.args["field"]["field"]
    assert float(jnp.max(jnp.abs(along - along[0]))) < 1e-12


@pytest.mark.parametrize("scheme", scheme_params())
def test_drag_takes_energy_at_c_omega_squared(scheme):
    """E(T) − E(0) = −∫ c |ω|² dt, to the scheme's accuracy (trapezoid over every step)."""
    scene = small("viscous_drag")
    dt = scene.dt / (4 if scheme == "euler" else 1)
    traj = run_unless_refused(scheme, "viscous_drag", scene, n_steps=400, dt=dt)
    if traj is None:
        return
    energy = kinetic_energy(traj.q, traj.omega, scene.inertia)
    c = scene.args["drag"]["coefficient"]
    power = c * jnp.sum(traj.omega**2, axis=-1)
    dissipated = float(jnp.sum(0.5 * (power[1:] + power[:-1])) * dt)
    lost = float(energy[0] - energy[-1])
    assert lost == pytest.approx(dissipated, rel=2e-2 if scheme == "euler" else 2e-4)
    assert lost > 0.05 * float(energy[0])  # the drag did something


@pytest.mark.slow
@pytest.mark.parametrize("scheme", scheme_params())
def test_time_and_velocity_dependent_scenes_follow_the_reference(scheme):
    for name in ("dipole_rotating_field", "viscous_drag"):
        scene = small(name)
        traj = run_unless_refused(scheme, name, scene, n_steps=100)
        if traj is None:
            continue
        ref = jaxrot.reference_rollout(
            scene.state, scene.inertia, traj.t, torque=scene.torque, args=scene.args, rtol=1e-12, atol=1e-12
        )
        error = float(jnp.max(quat.angle_between(traj.q, ref.q)))
        assert error < (2e-2 if scheme == "euler" else 1e-4), (name, error)


# --- coupled torques -------------------------------------------------------------------------


def _internal_torques(scene, q):
    """Dipole–dipole torques on all bodies at orientations ``q`` ``(N, 4)``, through the named vmap."""
    model = torques.DipoleInteraction()
    zeros = jnp.zeros(q.shape[:-1] + (3,))
    return jax.vmap(lambda qi, wi: model(0.0, qi, wi, scene.args), axis_name="particles")(q, zeros)


@pytest.mark.slow
def test_dipole_torques_match_the_energy_gradient():
    """τ_i = −(∂U/∂θ_i): the coupled torque is the energy's rotational derivative for every body."""
    scene = dipole_cloud(n_side=3, external_field=(0.0, 0.0, 0.0))
    model = torques.DipoleInteraction()
    q = scene.state.q

    def energy_after(thetas):
        return model.energy(0.0, quat.multiply(quat.exp(thetas), q), scene.args)

    gradient = jax.grad(energy_after)(jnp.zeros((q.shape[0], 3)))
    np.testing.assert_allclose(_internal_torques(scene, q), -gradient, rtol=1e-10, atol=1e-12)


def test_mutual_dipole_torques_balance_the_pins():
    """Σ τ_i = −Σ r_i × F_i: pinned dipoles pass momentum to the pins (it is not zero)."""
    scene = dipole_cloud(n_side=3, external_field=(0.0, 0.0, 0.0))
    total = jnp.sum(_internal_torques(scene, scene.state.q), axis=0)
    pins = torques.DipoleInteraction().pinning_torque(0.0, scene.state.q, scene.args)
    assert float(jnp.linalg.norm(total)) > 1e-2
    np.testing.assert_allclose(total, -pins, rtol=1e-10, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("external", [(0.0, 0.0, 0.0), (0.0, 0.0, 0.5)])
@pytest.mark.parametrize("scheme", ["zhao", "no_squish", "splitting"])
def test_dipole_cloud_momentum_changes_only_by_external_and_pin_torques(scheme, external):
    """ΔΣL = ∫ (Σ m_i × B_ext − Σ r_i × F_i) dt; energy conserved; the coupled reference agrees."""
    scene = dipole_cloud(n_side=3, external_field=external)
    dt, n = 0.001, 1000
    traj = run(scheme, scene, n_steps=n, dt=dt)
    momentum = jnp.sum(angular_momentum(traj.q, traj.omega, scene.inertia), axis=-2)
    external_torque = jax.vmap(
        lambda q: jnp.sum(jax.vmap(lambda qi: torques.UniformField()(0.0, qi, None, scene.args))(q), axis=0)
    )(traj.q)
    pins = jax.vmap(lambda q: torques.DipoleInteraction().pinning_torque(0.0, q, scene.args))(traj.q)
    rate = external_torque - pins
    expected = momentum[:1] + jnp.concatenate(
        [jnp.zeros((1, 3)), jnp.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt, axis=0)]
    )
    scale = float(jnp.max(jnp.linalg.norm(momentum - momentum[:1], axis=-1)))
    assert scale > 1e-2  # the momentum does change
    gap = float(jnp.max(jnp.linalg.norm(momentum - expected, axis=-1)))
    assert gap < 1e-4 * scale
    assert relative_energy_error(scene, traj) < 1e-4
    ref = jaxrot.reference_rollout(
        scene.state,
        scene.inertia,
        traj.t[::100],
        torque=scene.torque,
        args=scene.args,
        rtol=1e-12,
        atol=1e-12,
    )
    assert float(jnp.max(quat.angle_between(traj.q[::100], ref.q))) < 1e-4


def test_per_body_parameters_reach_their_own_body():
    scene = small("viscous_drag")
    state = jax.tree_util.tree_map(lambda x: jnp.stack([x, x, x]), scene.state)
    coefficients = jnp.array([0.0, 0.2, 1.0])
    args = {"drag": {"coefficient": jaxrot.per_body(coefficients)}}
    batch = jaxrot.rollout("zhao", state, scene.inertia, scene.dt, 50, torque=scene.torque, args=args)
    for i, c in enumerate(coefficients):
        alone = jaxrot.rollout(
            "zhao",
            scene.state,
            scene.inertia,
            scene.dt,
            50,
            torque=scene.torque,
            args={"drag": {"coefficient": c}},
        )
        np.testing.assert_allclose(batch.omega[:, i], alone.omega, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="per_body"):
        jaxrot.rollout(
            "zhao", state, scene.inertia, scene.dt, 5, torque=scene.torque,
            args={"drag": {"coefficient": jaxrot.per_body(jnp.zeros(2))}},
        )  # fmt: skip


def test_models_add_up():
    scene = small("heavy_top")
    model = torques.Gravity() + torques.ViscousDrag() + torques.UniformField()
    assert len(model.terms) == 3 and not model.coupled and not model.conservative
    args = {
        **scene.args,
        "drag": {"coefficient": jnp.array(0.3)},
        "field": {"moment_body": jnp.array([0.0, 0, 1]), "field": jnp.array([1.0, 0, 0])},
    }
    q, omega = scene.state
    expected = sum(m(0.0, q, omega, args) for m in model.terms)
    np.testing.assert_allclose(model(0.0, q, omega, args), expected, rtol=1e-15)
    assert (torques.Gravity() + torques.UniformField()).conservative


# --- pay only for what is declared -------------------------------------------------------------


def count_primitives(fn, *args):
    """Primitive counts of ``fn``'s traced program, descending into scan/jit/vmap bodies.

    ``"matrix_3x3"`` counts the products (``dot_general``) with a 3×3 operand.
    """
    counts = {}

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            counts[eqn.primitive.name] = counts.get(eqn.primitive.name, 0) + 1
            shapes = [getattr(v.aval, "shape", ()) for v in eqn.invars]
            if eqn.primitive.name == "dot_general" and any(tuple(s[-2:]) == (3, 3) for s in shapes):
                counts["matrix_3x3"] = counts.get("matrix_3x3", 0) + 1
            for param in eqn.params.values():
                for sub in param if isinstance(param, tuple | list) else (param,):
                    inner = getattr(sub, "jaxpr", sub)  # a ClosedJaxpr holds a Jaxpr
                    if hasattr(inner, "eqns"):
                        walk(inner)

    walk(jax.make_jaxpr(fn)(*args).jaxpr)
    return counts


def _rollout_ops(scheme, inertia, torque=None, args=None, drive=None):
    state = jaxrot.SCENES["heavy_top"]().state
    return count_primitives(
        lambda s: jaxrot.rollout(scheme, s, inertia, 0.01, 3, torque=torque, args=args, drive=drive).q, state
    )


def _zero_torque(t, q, omega, args):
    return jnp.zeros(3, q.dtype)


@pytest.mark.parametrize("scheme", contract_params())
def test_torque_free_scene_evaluates_no_torque(scheme):
    calls = []

    def spy(t, q, omega, args):
        calls.append(1)
        return jnp.zeros(3, q.dtype)

    moments = jnp.array([1.0, 2.0, 3.0])
    free = _rollout_ops(scheme, moments)
    with_torque = _rollout_ops(scheme, moments, torque=spy)
    assert calls  # the spy is traced when declared ...
    assert sum(free.values()) < sum(with_torque.values())  # ... and its stage work is gone without it


@pytest.mark.parametrize("scheme", contract_params())
def test_diagonal_inertia_does_no_matrix_products(scheme):
    moments = jnp.array([1.0, 2.0, 3.0])
    diagonal = _rollout_ops(scheme, moments, torque=_zero_torque)
    rot = quat.to_matrix(quat.exp(jnp.array([0.4, -0.7, 0.25])))
    full = _rollout_ops(scheme, rot @ jnp.diag(moments) @ rot.T, torque=_zero_torque)
    assert diagonal.get("matrix_3x3", 0) == 0
    assert full.get("matrix_3x3", 0) > 0


@pytest.mark.parametrize("scheme", contract_params())
def test_no_drive_runs_no_drive_code(scheme):
    moments = jnp.array([1.0, 2.0, 3.0])
    plain = _rollout_ops(scheme, moments, torque=_zero_torque)
    idle = jaxrot.Drive.imposed_moment(jnp.zeros(3), mask=jnp.array([False, False, False]))
    driven = _rollout_ops(scheme, moments, torque=_zero_torque, drive=idle)
    assert sum(plain.values()) < sum(driven.values())
    assert plain.get("select_n", 0) < driven.get("select_n", 0)


# --- the CLI -----------------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_lists_every_scene():
    proc = subprocess.run(
        [sys.executable, "-m", "jaxrot", "compare", "--list-scenes"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    for name in SCENES:
        assert name in proc.stdout


@pytest.mark.slow
def test_compare_runs_a_coupled_multi_body_scene():
    rows = compare(
        "dipole_cloud", t_end=0.2, coarse_steps=10, levels=1, schemes=["no_squish"],
        solvers=["diffrax_tsit5"], tolerances=(1e-8,), repeats=1, progress=False,
    )  # fmt: skip
    assert [r["particles"] for r in rows] == [16, 16]
    assert rows[1]["max_orientation_error_rad"] < 1e-6 < rows[0]["max_orientation_error_rad"] < 1e-2
