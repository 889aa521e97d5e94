"""`jaxrot.identify`'s default scheme sized to the step its controls force (`_identify._scheme`).

One record: a free body (moments 1, 1.5, 2; |ω| ≈ 1.05 rad/s, so the default step would be
0.6 / 1.05 = 0.57 s) under a smooth world-frame torque known through controls sampled every
0.05 s, its orientation read every 0.2 s with σ = 1e-3 rad. The controls put a model step on
every control time, 0.05 s: a 0.05 rad turn per step, where `zhao`'s (second order) whitened
error on the start's model is 0.54, above the bound, and `rkmk4`'s (fourth order) 1.4e-4
(measured once; at 0.01 s they are 0.034 and 3e-7).
"""

import collections
import dataclasses
import logging
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat


SIGMA_Q = 1e-3
MOMENTS = jnp.array([1.0, 1.5, 2.0])


def _torque(t, q, omega, args):
    return 0.05 * jnp.stack([jnp.sin(t), jnp.cos(1.3 * t), jnp.sin(0.7 * t)])


@pytest.fixture(scope="module")
def experiment():
    state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 0.1, 1.0]))
    record = jaxrot.rollout("rkmk_dopri5", state, MOMENTS, 0.01, 600, torque=_torque, save_every=20)
    noise = np.random.default_rng(0).normal(scale=SIGMA_Q, size=(record.q.shape[0], 3))
    q = quat.multiply(record.q, quat.exp(jnp.asarray(noise)))
    t_c = np.linspace(0.0, 6.0, 121)
    tau_c = np.stack([np.asarray(_torque(s, None, None, None)) for s in t_c])
    return jaxrot.Experiment(record.t, q=q, sigma_q=SIGMA_Q, control=(t_c, tau_c))


def _stages(experiment, **kwargs):
    from jaxrot._fit._identify._check import check_arguments
    from jaxrot._fit._identify._problem import build_problem
    from jaxrot._fit._identify._start import starting_point

    options = dict(
        torque=None, args=None, free_args=None, inertia0=None, free_inertia=True, scheme=None, dt=None,
        q0=None, omega0=None, max_iter=100, ftol=1e-10, rcond=None, sensors=None,
    )  # fmt: skip
    settings = check_arguments(experiment, **(options | kwargs))
    start = starting_point(settings)
    return settings, start, build_problem(settings, start)


def test_the_cheapest_scheme_within_the_bound_is_chosen(experiment):
    """zhao's measured error is above `BIAS_BOUND`, rkmk4's (Cayley) below it: rkmk4 runs the fit; a
    scheme the user names, or σ to estimate, keep the default. Residual programs only (no fit)."""
    from jaxrot._fit._identify import _scheme

    settings, start, problem = _stages(experiment)
    assert problem.max_step < _scheme.FORCED * min(start.max_step, 0.2)
    chosen, choice = _scheme.choose_scheme(settings, problem, start.max_step)
    assert choice.scheme.name == "rkmk4" and chosen.model.scheme is choice.scheme
    assert choice.note.startswith("rkmk4 (chosen: the controls fix the step at 0.05")
    zhao = dataclasses.replace(problem.model, scheme=_scheme.CANDIDATES[0])
    phi0 = jnp.asarray(problem.phi0)
    reference = np.asarray(_scheme._residuals(phi0, problem.model))
    assert np.linalg.norm(np.asarray(_scheme._residuals(phi0, zhao)) - reference) > _scheme.BIAS_BOUND

    named = _stages(experiment, scheme="rkmk_dopri5")
    assert _scheme.choose_scheme(named[0], named[2], named[1].max_step)[1].note == ""
    blind = jaxrot.Experiment(experiment.t, q=experiment.q, control=experiment.control)
    estimated = _stages(blind)
    assert _scheme.choose_scheme(estimated[0], estimated[2], estimated[1].max_step)[1].note == ""


@pytest.mark.slow
def test_the_chosen_scheme_fits_within_a_tenth_of_a_standard_error(experiment):
    """The bound's claim on the fit itself: the rkmk4 fit and the default scheme's agree within 0.1
    standard errors in every inertia element and every initial angular velocity component (the fitted
    parameters but the initial orientations, whose standard errors are in another chart); the summary
    names the choice."""
    chosen = jaxrot.identify(experiment)
    default = jaxrot.identify(experiment, scheme=jaxrot.schemes.RKMKDopri5(chart="cayley"))
    assert chosen.scheme.name == "rkmk4" and chosen.converged and default.converged
    assert "scheme rkmk4 (chosen:" in chosen.summary() and "chosen:" not in default.summary()
    gap = np.abs(np.asarray(chosen.inertia) - np.asarray(default.inertia))
    assert np.max(gap / np.asarray(default.stderr.inertia)) < 0.1
    gap = np.abs(np.asarray(chosen.omega0) - np.asarray(default.omega0))
    assert np.max(gap / np.asarray(default.stderr.omega0)) < 0.1


class _Compiles(logging.Handler):
    """The programs JAX compiles while attached: ``(name, argument shapes)`` of each "Compiling" log line."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.programs = []

    def emit(self, record):
        match = re.match(
            r"Compiling (\S+) with global shapes and types (.*)\. Argument mapping", record.getMessage()
        )
        if match:
            self.programs.append(match.groups())


def test_one_residual_and_one_jacobian_program_per_call(experiment):
    """The scheme is chosen in ONE residual program (the scheme a runtime index, `_scheme.SchemeSwitch`)
    and the fit runs in ONE Jacobian program: here zhao fails the bound and rkmk4 passes it, so the
    choice runs three schemes (before: three residual programs), and no program compiles twice for the
    same shapes. A record shorter than the fixture's: shapes no other test compiles first."""
    short = jaxrot.Experiment(
        experiment.t[:26], q=experiment.q[:26], sigma_q=SIGMA_Q,
        control=(experiment.control[0][:101], experiment.control[1][:101]),
    )  # fmt: skip
    handler = _Compiles()
    logger = logging.getLogger("jax")
    previous = jax.config.jax_log_compiles
    logger.addHandler(handler)
    jax.config.update("jax_log_compiles", True)
    try:
        fit = jaxrot.identify(short)
    finally:
        jax.config.update("jax_log_compiles", previous)
        logger.removeHandler(handler)
    assert fit.scheme.name == "rkmk4" and fit.converged
    names = [name for name, _ in handler.programs]
    assert sum("_residuals" in name for name in names) == 1, names
    assert sum("_staged_gauss_newton" in name for name in names) == 1, names
    twice = [program for program, count in collections.Counter(handler.programs).items() if count > 1]
    assert not twice, twice
