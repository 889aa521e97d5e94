"""`_mujoco_sysid`: `mujoco.sysid` fitting the inertia to MuJoCo's own telemetry, as a user writes it.

Skipped where ``mujoco[sysid]`` is not installed (``pip install -e ".[mujoco]"``). The fits are
timed by the benchmark, never here.
"""

import numpy as np
import pytest


# All in the slow set: .ci/run installs MuJoCo for it (README's quick start does not), so these would
# be skipped in CI's default run.
pytestmark = pytest.mark.slow
sysid = pytest.importorskip("mujoco.sysid")
if not hasattr(sysid, "optimize"):
    pytest.skip("mujoco.sysid without its extra: pip install 'mujoco[sysid]'", allow_module_level=True)

import _mujoco_sysid as ms  # noqa: E402
import _mujoco_sysid_sensors as mss  # noqa: E402
import _mujoco_telemetry as mt  # noqa: E402
import mujoco  # noqa: E402


def _residual_at_truth(manoeuvres):
    problem = ms.sysid_problem(manoeuvres, inertia0=mt.INERTIA)
    x = problem.params.as_vector()  # the start: the true inertia, and the first (noise-free) samples
    residuals, _, _ = problem.residual_fn(x, problem.params)
    return np.concatenate(residuals)


def test_sysid_residual_vanishes_at_the_truth():
    """At the true inertia and initial states sysid's prediction is MuJoCo's record: the controls held
    per step, the prediction reaching the last sample, and each sample stamped as MuJoCo stamps its
    rows (time + dt). Stamped at its own time instead, every sample is one step off."""
    manoeuvres = mt.manoeuvres(duration=1.0)
    residual = _residual_at_truth(manoeuvres)
    assert residual.size == 3 * 101 * 7  # every sample of every sensor column
    # Residuals are divided by each column's norm / √2 (~10 here); round-off of 1000 steps.
    assert np.abs(residual).max() < 1e-11
    unshifted = [m._replace(t=m.t - mt.TIMESTEP) for m in manoeuvres]
    assert np.abs(_residual_at_truth(unshifted)).max() > 1e-6


def test_sysids_pseudo_inertia_writer_does_not_compile_on_mujoco_4_0():
    """The reason `_mujoco_sysid` writes ``fullinertia`` itself: sysid's ``InertiaType.Pseudo``
    modifier sets ``iquat`` to NaN, which MuJoCo 4.0.0's compiler rejects. If this fails, sysid's own
    writer works: use it in `_mujoco_sysid.sysid_problem`."""
    spec = mujoco.MjSpec.from_string(mt.model_xml())
    param = sysid.body_inertia_param(spec, spec.compile(), "body", sysid.InertiaType.Pseudo)
    params = sysid.ParameterDict()
    params.add(param)
    with pytest.raises(ValueError, match="mass and inertia of moving bodies"):
        sysid.apply_param_modifiers(params, spec)


def test_sysid_recovers_the_inertia_from_noise_free_data():
    """From a sphere (0.045 kg m²) and the first samples, three 2 s manoeuvres: the tensor MuJoCo
    integrated, to the finite-difference Jacobian's reach (measured 1.6e-12 relative)."""
    manoeuvres = mt.manoeuvres(duration=2.0)
    fit = ms.sysid_fit(manoeuvres)
    truth = mt.true_inertia()
    assert np.abs(fit.inertia - truth).max() < 1e-8 * np.abs(truth).max()
    for q0, omega0, m in zip(fit.q0, fit.omega_body0, manoeuvres, strict=True):
        np.testing.assert_allclose(q0, m.q0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(omega0, m.omega_body0, rtol=0, atol=1e-9)
    assert len(fit.names) == 6 + 3 * 6 and fit.covariance.shape == (24, 24) and fit.wall_s > 0


def test_sysid_noisy_fit_is_within_its_standard_errors():
    """One noise seed, three 5 s manoeuvres: every inertia element within 4.5 of sysid's standard
    errors (delta method on its covariance; p < 1e-4 per element if they were calibrated), and the
    95 % half-widths sysid reports are 1.96 of its standard errors (a t quantile at ~9000 dof)."""
    fit = ms.sysid_fit(mt.manoeuvres(duration=5.0, noise_seed=11))
    z = (fit.inertia - mt.true_inertia()) / fit.inertia_stderr
    assert np.abs(z).max() < 4.5, z
    stderr = np.sqrt(np.diag(fit.covariance))
    np.testing.assert_allclose(fit.halfwidth95, 1.96 * stderr, rtol=1e-3)


def _truth_vector(problem, manoeuvres):
    """sysid's parameter vector at the truth of `_mujoco_telemetry.sensor_manoeuvres`: the true sensor
    flaws, and each rollout's initial state at the controls' start (the seed's initial state)."""
    import jax.numpy as jnp

    from jaxrot import quaternion as quat

    params = problem.params
    for name in mss.SENSOR_NAMES:
        params[name].value = np.atleast_1d(np.asarray(mt.TRUE_SENSORS[name], dtype=float)).copy()
    for j, (m, seed) in enumerate(zip(manoeuvres, mt.SEEDS, strict=True)):
        q0, omega_body0 = mt.initial_state(seed)
        params[f"gyro_bias_{j}"].value = mt.TRUE_SENSORS["gyro_bias"][j].copy()
        offset = quat.log(quat.multiply(quat.conjugate(jnp.asarray(m.q[0])), jnp.asarray(q0)))
        params[f"q0_offset_{j}"].value = np.asarray(offset)
        params[f"omega0_{j}"].value = omega_body0.copy()
    return params.as_vector()


def test_sysid_sensor_residual_vanishes_at_the_truth():
    """`_mujoco_sysid_sensors` expresses every flaw of `sensor_manoeuvres`: at the true inertia, flaws
    and initial states sysid's residual is round-off over every sample (the delays are whole MuJoCo
    steps, so the interpolated prediction is an exact row); with the flaws at their ideal values it
    is not (the mount alone is 0.023 rad, 200 σ)."""
    manoeuvres = mt.sensor_manoeuvres(duration=1.0)
    problem = mss.sysid_sensor_problem(manoeuvres, inertia0=mt.INERTIA)
    x = _truth_vector(problem, manoeuvres)
    residual = np.concatenate(problem.residual_fn(x, problem.params)[0])
    assert residual.size == 3 * 100 * 7  # every sample (10 ms to 1 s) of every sensor column
    assert np.abs(residual).max() < 1e-11
    ideal = x.copy()
    names = [p.name for p in problem.params.values() for _ in range(p.size)]
    for i, name in enumerate(names):
        if name in mss.SENSOR_NAMES or name.startswith("gyro_bias"):
            ideal[i] = 1.0 if name == "gyro_scale" else 0.0
    residual = np.concatenate(problem.residual_fn(ideal, problem.params)[0])
    assert np.abs(residual).max() > 1e-4


def test_sysid_recovers_the_inertia_and_the_sensor_flaws_from_noise_free_data():
    """From a sphere, ideal sensors and the first samples, three 2 s manoeuvres through real sensors:
    the inertia to 1e-6 relative and every flaw to 1e-6 of its unit (measured 2.3e-7 relative for the
    inertia: sysid stops on its gradient norm, its cost then 6e-13). A mount about an identity base
    (module docstring of `_mujoco_sysid_sensors`) stays at 0 here: its finite-difference column is zero."""
    manoeuvres = mt.sensor_manoeuvres(duration=2.0)
    fit = mss.sysid_sensor_fit(manoeuvres)
    truth = mt.true_inertia()
    assert np.linalg.norm(fit.inertia - truth) < 1e-6 * np.linalg.norm(truth)
    for name, value in mt.TRUE_SENSORS.items():
        np.testing.assert_allclose(
            np.ravel(fit.extra[name]), np.ravel(value), rtol=0, atol=1e-6, err_msg=name
        )
