"""jaxrot.jax_md.brownian: overdamped rigid bodies in jax_md's call (jax_md's own cannot run them), and
the rotational friction per body axis of `brownian` and `nvt_langevin`.

Statistics over ``N`` independent bodies: a mean's standard error is the bodies' spread over ``√N``;
each check is at 4 standard errors. The closed forms: free rotational diffusion of an asymmetric body
(Favro, Phys. Rev. 119, 53 (1960)): with ``M = R(0)ᵀ R(t)`` and the body-side generator
``Σ_k D_k E_k²`` (``E_k`` the generator of rotations about body axis ``k``), ``⟨M⟩ = exp(t G₁)`` and
``⟨M ⊗ M⟩ = exp(t G₂)``, ``G₂ = Σ_k D_k (E_k ⊗ 1 + 1 ⊗ E_k)²``: the decays ``⟨P₁(u_l(t)·u_l(0))⟩ =
⟨M_ll⟩ = e^{−(D_j + D_k) t}`` and ``⟨P₂⟩ = (3⟨M_ll²⟩ − 1)/2`` per body axis ``l``; a dipole ``μ`` in a
field ``B``: ``⟨cos θ⟩ = L(μB/kT) = coth(μB/kT) − kT/(μB)``.
"""

import functools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest


with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
    jax_md = pytest.importorskip(
        "jax_md",
        reason='jax_md is not installed: pip install -e ".[jax_md]" (Python 3.12: it excludes jax 0.10.2)',
    )
    from jax_md import rigid_body, simulate, space

import jaxrot.jax_md as jm
from jaxrot import quaternion as quat
from jaxrot.jax_md._common import promoting


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import jax_md_systems as systems  # noqa: E402


KT = 1.0
FRICTION = (1.0, 2.0, 4.0)  # rotational, per body axis: D = kT/ζ = (1, 1/2, 1/4), all three distinct
GAMMA_CENTRE = 0.5  # jax_md's friction over mass: the centres' D = kT / (m γ) = 1/2 (mass 4)


def test_favro_closed_form_is_the_textbook_p1():
    """The matrix form's P₁ is e^{−(D_j + D_k) t} per axis; a sphere's P₂ is e^{−6Dt}."""
    p1, _ = systems.favro((1.0, 0.5, 0.25), 0.7)
    np.testing.assert_allclose(p1, np.exp(-0.7 * np.array([0.75, 1.25, 1.5])), rtol=1e-12)
    _, p2 = systems.favro((0.3, 0.3, 0.3), 0.7)
    np.testing.assert_allclose(p2, np.exp(-6 * 0.3 * 0.7), rtol=1e-12)


@functools.cache
def _free_run(n=4000, dt=0.05, steps=20):
    """``n`` free tetrahedra, friction `FRICTION` per axis, over ``steps`` of ``dt`` (t = 1): the start
    and end states, and jax_md's own Brownian step on the centres alone from the same key."""
    _, shift, body = systems.free_system(n)
    init_fn, apply_fn = jm.brownian(
        systems.free_energy,
        shift,
        dt,
        KT,
        rigid_body.RigidBody(GAMMA_CENTRE, 1.0),
        rotational_friction=jnp.asarray(FRICTION),
    )
    start = init_fn(jax.random.key(2), body, mass=systems.shape().mass())
    end = jax.jit(promoting(lambda s: jax.lax.fori_loop(0, steps, lambda i, s_: apply_fn(s_), s)))(start)
    init_md, apply_md = simulate.brownian(lambda r: 0.0 * jnp.sum(r), shift, dt, KT, GAMMA_CENTRE)
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        centres = init_md(jax.random.key(2), body.center, mass=4.0)
        centres = jax.jit(lambda s: jax.lax.fori_loop(0, steps, lambda i, s_: apply_md(s_), s))(centres)
    return start, end, centres.position, dt * steps


def test_free_body_diffuses_per_axis_as_favro():
    """4000 free asymmetric bodies, D = (1, 1/2, 1/4) about their axes, t = 1 in 20 steps: each body
    axis' ⟨P₁⟩ and ⟨P₂⟩ equal Favro's within 4 standard errors (≈ 0.008: 0.03; the three axes' P₁,
    0.47, 0.29, 0.22, are 20+ errors apart, so a friction on the wrong axes fails). The splitting is
    weak order 2 here (three distinct D): docs/jax_md_brownian.json (16000 bodies, errors ≈ 0.005)
    finds it within 0.011 of Favro at t = 0.5, 1, 2, below the 0.03 allowed here."""
    start, end, _, t = _free_run()
    rotation = jax.vmap(quat.to_matrix)
    r0, r1 = rotation(start.position.orientation.vec), rotation(end.position.orientation.vec)
    m = np.einsum("nai,naj->nij", r0, r1)
    cosines = np.stack([m[:, k, k] for k in range(3)], axis=1)  # u_l(t)·u_l(0) per body axis
    p1, p2 = systems.favro(KT / np.asarray(FRICTION), t)
    for samples, expected in ((cosines, p1), (1.5 * cosines**2 - 0.5, p2)):
        mean, error = samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(len(samples))
        assert np.all(np.abs(mean - expected) < 4 * error), (mean, expected, error)


def test_free_centres_are_jax_mds_brownian():
    """The centres take jax_md's Brownian step from jax_md's key split: equal to ``simulate.brownian`` on
    the centres alone (point particles of mass 4) to round-off; their mean squared displacement is
    2·d·D·t, D = kT / (m γ) = 1/2 (within 4 standard errors, ≈ 0.013 relative)."""
    start, end, centres, t = _free_run()
    np.testing.assert_allclose(end.position.center, centres, rtol=1e-13, atol=1e-13)
    squared = np.sum((np.asarray(end.position.center) - np.asarray(start.position.center)) ** 2, axis=1)
    expected = 2 * 3 * KT / (4.0 * GAMMA_CENTRE) * t
    assert abs(squared.mean() - expected) < 4 * squared.std(ddof=1) / np.sqrt(len(squared)), squared.mean()


@pytest.mark.slow
def test_dipole_in_a_field_follows_the_langevin_function():
    """4000 dipoles (body x, μB = 2 kT along world z), jax_md's gamma convention (G = 1: ζ = G / Σ 1/I
    ≈ 2.8, D ≈ 0.36), dt = 0.02, 4 time units of burn-in (≥ 2.8 relaxation times 1/(2D) each) then
    the mean of ⟨cos θ⟩ over 8 snapshots: L(2) = coth 2 − 1/2 within 4 standard errors (per-body time
    averages, independent across bodies: ≈ 0.003). The force is held over each step (weak order 1):
    docs/jax_md_brownian.json (16000 bodies) has −0.003 ± 0.002 here, and −0.004 ± 0.0004 at μB = 8 kT
    (the held torque's bias grows with μB Δt / ζ)."""
    n, field = 4000, 2.0

    def energy_fn(position, **kwargs):
        axis = rigid_body.quaternion_rotate(position.orientation, jnp.array([1.0, 0.0, 0.0]))
        return -field * jnp.sum(axis[:, 2])

    _, shift, body = systems.free_system(n)
    init_fn, apply_fn = jm.brownian(energy_fn, shift, 0.02, KT, 1.0)

    @jax.jit
    @promoting
    def run(state):
        def snapshot(s, _):
            s = jax.lax.fori_loop(0, 50, lambda i, s_: apply_fn(s_), s)
            return s, rigid_body.quaternion_rotate(s.position.orientation, jnp.array([1.0, 0.0, 0.0]))[:, 2]

        state, _ = jax.lax.scan(snapshot, state, None, length=4)
        return jax.lax.scan(snapshot, state, None, length=8)[1]

    per_body = np.asarray(run(init_fn(jax.random.key(3), body, mass=systems.shape().mass()))).mean(axis=0)
    expected = 1 / np.tanh(field / KT) - KT / field
    error = per_body.std(ddof=1) / np.sqrt(n)
    assert abs(per_body.mean() - expected) < 4 * error, (per_body.mean(), expected, error)


def test_jax_mds_own_brownian_cannot_take_rigid_bodies():
    """What `brownian` is for: jax_md's ``simulate.brownian`` flattens its state with
    ``dataclasses.astuple``, which turns the ``RigidBody`` position into a plain tuple, and its shift
    then fails: ``'tuple' object has no attribute 'center'`` in the force of free bodies,
    ``... 'orientation'`` in `rigid_body.point_energy`'s (docs/jax_md_upstream_report.md). If jax_md
    fixes it, this fails and the docs change."""
    _, shift, body = systems.free_system(4)
    init_fn, apply_fn = simulate.brownian(systems.free_energy, shift, 1e-3, KT)
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        state = init_fn(jax.random.key(0), body, mass=systems.shape().mass())
        with pytest.raises(AttributeError, match="'tuple' object has no attribute"):
            apply_fn(state)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda e, s: jm.brownian(e, s, 0.0, 1.0), "`dt`"),
        (lambda e, s: jm.brownian(e, s, 1e-3, -1.0), "`kT`"),
        (lambda e, s: jm.brownian(e, s, 1e-3, 1.0, gamma=0.0), "`gamma`"),
        (lambda e, s: jm.brownian(e, s, 1e-3, 1.0, rigid_body.RigidBody(1.0, -1.0)), "gamma.orientation"),
        (lambda e, s: jm.brownian(e, s, 1e-3, 1.0, scheme="baoab"), "'brownian_splitting'"),
        (lambda e, s: jm.brownian(e, s, 1e-3, 1.0, rotational_friction=jnp.ones(2)), "rotational_friction"),
        (lambda e, s: jm.brownian(e, s, 1e-3, 1.0, rotational_friction=-jnp.ones(3)), "rotational_friction"),
        (lambda e, s: jm.nvt_langevin(e, s, 1e-3, 1.0, rotational_friction=jnp.ones((4, 2))), "friction"),
        (lambda e, s: jm.brownian(None, s, 1e-3, 1.0), "energy_or_force_fn"),
        (lambda e, s: jm.brownian(e, None, 1e-3, 1.0), "shift_fn"),
    ],
)
def test_bad_input_is_refused_before_compiling(call, message):
    _, shift = space.free()
    with pytest.raises(ValueError, match=message):
        call(systems.free_energy, shift)


def test_positions_must_be_3d_rigid_bodies():
    """`brownian`'s step refuses positions that are not ``RigidBody``s of quaternions, as
    `nvt_langevin`'s and `nve`'s do (the one check of `jaxrot.jax_md._common`), naming its call."""
    _, shift = space.free()
    _, apply_fn = jm.brownian(systems.free_energy, shift, 1e-3, KT)
    state = simulate.BrownianState(jnp.zeros((2, 3)), jnp.ones((2,)), jax.random.key(0))
    with pytest.raises(ValueError, match=r"jaxrot\.jax_md\.brownian steps 3-d rigid bodies.*RigidBody"):
        apply_fn(state)


@pytest.mark.parametrize("simulator", ["brownian", "nvt_langevin"])
def test_per_body_friction_of_another_length_is_refused_while_tracing(simulator):
    """A ``(M, 3)`` friction for N ≠ M bodies passes the construction check (N is not known then) and is
    refused with a ValueError when the first step is traced, before XLA compiles it (not a shape error
    from inside vmap)."""
    _, shift, body = systems.free_system(4)
    init_fn, apply_fn = getattr(jm, simulator)(
        systems.free_energy, shift, 1e-3, KT, rotational_friction=jnp.ones((3, 3))
    )
    state = init_fn(jax.random.key(0), body, mass=systems.shape().mass())
    with pytest.raises(ValueError, match="3 rows but there are 4 bodies"):
        apply_fn(state)


def test_langevin_friction_per_axis_sets_each_axis_rate():
    """`nvt_langevin(..., rotational_friction=ζ)`: 4000 free tetrahedra at rest, one step of dt = 0.01 with
    ζ_l / I_l = (50, 200, 12.5): each axis heats to ⟨L_l²/I_l⟩ = kT (1 − e^{−2 ζ_l Δt / I_l}) = (0.632,
    0.982, 0.221) kT, within 4 standard errors (√(2/N) of it: 2.2 %); the rotor's mixing of the axes
    over a step (turns of ~0.003 rad) is far below. One friction for all axes (jax_md's) would heat
    them alike."""
    n, dt = 4000, 0.01
    moments = np.asarray(systems.MOMENTS)
    rates = np.array([50.0, 200.0, 12.5])
    _, shift, body = systems.free_system(n)
    init_fn, apply_fn = jm.nvt_langevin(
        systems.free_energy, shift, dt, KT, 10.0, rotational_friction=jnp.asarray(rates * moments)
    )
    rest = rigid_body.RigidBody(jnp.zeros((n, 3)), rigid_body.Quaternion(jnp.zeros((n, 4))))
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        state = apply_fn(init_fn(jax.random.key(4), body, mass=systems.shape().mass(), momenta=rest))
    q, p = state.position.orientation.vec, state.momentum.orientation.vec
    heat = np.asarray(jm.angular_momentum(q, p)) ** 2 / moments
    expected = KT * (1 - np.exp(-2 * rates * dt))
    mean, error = heat.mean(axis=0), heat.std(axis=0, ddof=1) / np.sqrt(n)
    assert np.all(np.abs(mean - expected) < 4 * error), (mean, expected, error)


@pytest.mark.slow
def test_interacting_tetrahedra_stay_finite_and_isotropic():
    """jax_md's 40 soft-sphere tetrahedra (density 0.1, kT = 1, gamma 1: ζ ≈ 2.8, the centres' m γ = 4),
    dt = 0.01, 200 snapshots 0.5 apart after 5 time units: every state finite and unit quaternions; the
    Boltzmann law of one body's orientation in the cubic box is uniform, so each body axis has
    ⟨(u_l · e_z)²⟩ = 1/3 within 4 standard errors (of 50 block means of 4 snapshots, 2 time units
    each, longer than the rotational relaxation time 1/(6D) ≈ 0.5 of u²; ≈ 0.007), and the soft-sphere
    energy stays bounded (no overlap blows up: max U per body < 1)."""
    energy_fn, shift, body = systems.tetrahedra()
    init_fn, apply_fn = jm.brownian(energy_fn, shift, 0.01, KT, 1.0)

    @jax.jit
    @promoting
    def run(state):
        def snapshot(s, _):
            s = jax.lax.fori_loop(0, 50, lambda i, s_: apply_fn(s_), s)
            axes = jax.vmap(quat.to_matrix)(s.position.orientation.vec)[:, 2, :]  # e_z · u_l per body axis
            norm = jnp.linalg.norm(s.position.orientation.vec, axis=-1)
            return s, (jnp.mean(axes**2, axis=0), energy_fn(s.position) / 40, jnp.max(jnp.abs(norm - 1)))

        state, _ = jax.lax.scan(snapshot, state, None, length=10)
        return jax.lax.scan(snapshot, state, None, length=200)[1]

    squares, energies, norm_errors = (
        np.asarray(x) for x in run(init_fn(jax.random.key(6), body, mass=systems.shape().mass()))
    )
    assert np.all(np.isfinite(squares)) and np.all(np.isfinite(energies))
    assert np.max(norm_errors) < 1e-12 and np.max(energies) < 1.0, (np.max(norm_errors), np.max(energies))
    blocks = squares.reshape(50, 4, 3).mean(axis=1)  # blocks of 2 time units: near-independent
    mean, error = blocks.mean(axis=0), blocks.std(axis=0, ddof=1) / np.sqrt(len(blocks))
    assert np.all(np.abs(mean - 1 / 3) < 4 * error), (mean, error)
