"""`jaxrot.identify` on telemetry made by MuJoCo 4.0 (slow; skipped where ``mujoco`` is absent).

MuJoCo integrates a free body under body-frame motor torques held over each 1 ms step (RK4) and
records its orientation and gyro at 100 Hz (`_mujoco_telemetry`: its time stamps and frames
checked there). jaxrot fits it with its own model: the controls as MuJoCo applies them
(``control_frame="body"``, ``control_hold="previous"``), the model's steps on the 1 ms switches.
"""

import numpy as np
import pytest


pytestmark = pytest.mark.slow
pytest.importorskip("mujoco")

import _mujoco_telemetry as mt  # noqa: E402

import jaxrot  # noqa: E402


def experiments_of(manoeuvres, sigma_q=mt.SIGMA_Q, sigma_omega=mt.SIGMA_OMEGA):
    """`jaxrot.Experiment`s of MuJoCo's manoeuvres: body-frame torques held per MuJoCo step."""
    return [
        jaxrot.Experiment(
            m.t,
            q=m.q,
            omega_body=m.omega_body,
            sigma_q=sigma_q,
            sigma_omega=sigma_omega,
            control=(m.t_c, m.tau_c),
            control_frame="body",
            control_hold="previous",
        )  # fmt: skip
        for m in manoeuvres
    ]


def test_noise_free_mujoco_data_give_mujocos_inertia_to_1e_6():
    """Three 2 s manoeuvres, noise-free: the tensor MuJoCo integrated (`mt.true_inertia`, its
    body-frame tensor from the compiled principal moments and frame) to 1e-6 relative. MuJoCo's RK4
    at 1 ms errs by ~(|ω| Δt)⁵ ≈ 1e-18 rad a step here, jaxrot's fifth-order model at the same
    steps by as little: what is left is the fit's convergence."""
    fit = jaxrot.identify(experiments_of(mt.manoeuvres(duration=2.0)))
    truth = mt.true_inertia()
    assert fit.converged and fit.unidentified == ()
    np.testing.assert_allclose(np.asarray(fit.inertia), truth, rtol=1e-6, atol=0)  # measured 1.9e-11
    q0 = np.stack([m.q0 for m in mt.manoeuvres(duration=2.0)])
    np.testing.assert_allclose(np.abs(np.sum(np.asarray(fit.q0) * q0, axis=-1)), 1.0, atol=1e-12)
