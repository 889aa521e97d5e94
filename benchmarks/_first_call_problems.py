"""The problems of `benchmarks/first_call.py`: for each entry, the function a user's first call compiles
(with example arguments, where it is one jitted function) and that call itself. Each builder runs in
the measuring process, which then empties JAX's in-memory caches: what it compiles to make its data
does not count."""

NO_JAX_MD = "jax_md not installed (Python 3.12 with `pip install -e '.[jax_md]'`)"


class Skip(Exception):
    """An entry this environment cannot run (a missing optional package), with the reason."""


def _heavy_top(kind, method):
    """``benchmarks/compile.py``'s heavy-top programs: (function, example arguments, the user's call)."""
    import jax
    from compile import SAVE_EVERY, STEPS, _programs

    import jaxrot
    from jaxrot.scenes import heavy_top

    programs, example = _programs(method)
    fn = programs[kind]
    if kind == "forward" and not method.startswith("diffrax"):
        scene = heavy_top()

        def call():  # what a user writes: rollout at top level
            return jaxrot.rollout(
                method, scene.state, scene.inertia, scene.dt, STEPS, torque=scene.torque,
                args=scene.args, save_every=SAVE_EVERY,
            ).q  # fmt: skip
    else:
        jitted = jax.jit(fn)

        def call():
            return jitted(*example)

    return fn, example, call


def _fluid(method):
    import diffrax
    import jax
    import jax.numpy as jnp
    from compile import SAVE_EVERY, STEPS

    import jaxrot
    from jaxrot.comparison._fluid import plain_fluid_torque
    from jaxrot.scenes import spheroid_shear

    scene = spheroid_shear(stokes=0.1)
    ts = scene.dt * SAVE_EVERY * jnp.arange(STEPS // SAVE_EVERY + 1, dtype=jnp.float64)
    if method == "exp_rk4":

        def fn(state, inertia):
            return jaxrot.rollout(
                "exp_rk4", state, inertia, scene.dt, STEPS, fluid=scene.fluid, save_every=SAVE_EVERY
            ).q
    else:
        torque = plain_fluid_torque(scene)

        def fn(state, inertia):
            sol = diffrax.diffeqsolve(
                jaxrot.RigidBodyTerm(inertia, torque), diffrax.Tsit5(), 0.0, STEPS * scene.dt, scene.dt,
                state, saveat=diffrax.SaveAt(ts=ts), max_steps=STEPS,
            )  # fmt: skip
            return sol.ys.q

    example = (scene.state, scene.inertia)
    jitted = jax.jit(fn)
    call = (lambda: fn(*example)) if method == "exp_rk4" else (lambda: jitted(*example))
    return fn, example, call


def _thermal():
    import jax
    from compile import SAVE_EVERY, STEPS

    import jaxrot
    from jaxrot.scenes import magnetic_nanoparticles_inertial

    scene = magnetic_nanoparticles_inertial(n=256)

    def fn(state, key):
        return jaxrot.rollout(
            "baoab", state, scene.inertia, scene.dt, STEPS, torque=scene.torque, args=scene.args,
            fluid=scene.fluid, key=key, save_every=SAVE_EVERY,
        ).q  # fmt: skip

    example = (scene.state, jax.random.key(0))
    return fn, example, lambda: fn(*example)


def _diffeqsolve(solver_name):
    import diffrax
    import jax
    import jax.numpy as jnp

    import jaxrot
    from jaxrot.scenes import heavy_top

    scene = heavy_top()
    solver = jaxrot.solver("rkmk_dopri5") if solver_name == "rkmk_dopri5" else diffrax.Tsit5()
    ts = jnp.linspace(0.0, 2.0, 21)

    def fn(inertia, args):
        sol = diffrax.diffeqsolve(
            jaxrot.RigidBodyTerm(inertia, scene.torque), solver, 0.0, 2.0, scene.dt, scene.state,
            args=args, saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8),
        )  # fmt: skip
        return sol.ys.q

    example, jitted = (scene.inertia, scene.args), jax.jit(fn)
    return fn, example, lambda: jitted(*example)


def _satellite(side):
    """`benchmarks/identify_speed.py`'s problem: jaxrot's fit or the diffrax + optimistix one."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optimistix as optx
    from _telemetry import dipole_torque, satellite_experiments
    from identify_speed import INERTIA0, diffrax_model, residuals, stack

    import jaxrot
    from jaxrot import quaternion as quat

    experiments, _ = satellite_experiments(0)
    data = stack(experiments)
    q_start = data["q"][:, 0]
    omega_start = quat.rotate(q_start, data["omega_body"][:, 0])
    if side == "identify":
        return lambda: jaxrot.identify(
            experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True},
            inertia0=INERTIA0, q0=np.asarray(q_start), omega0=np.asarray(omega_start),
        ).inertia  # fmt: skip
    import diffrax

    model = diffrax_model(diffrax.Tsit5(), 1, data)
    sigmas = (experiments[0].sigma_q, experiments[0].sigma_omega)
    start = {
        "inertia": jnp.asarray(INERTIA0[(0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2)]),
        "dipole": jnp.zeros(3),
        "dq0": jnp.zeros((3, 3)),
        "omega0": omega_start,
    }

    @jax.jit
    def solve(p0):
        sol = optx.least_squares(
            residuals, optx.GaussNewton(rtol=1e-4, atol=1e-4), p0,
            args=(model, data, q_start, *sigmas), max_steps=100, throw=False,
        )  # fmt: skip
        return sol.value

    return lambda: solve(start)


def _mujoco(side):
    try:
        import _mujoco_sysid as ms
        import _mujoco_telemetry as mt
        from mujoco import sysid

        if not hasattr(sysid, "optimize"):
            raise ImportError("mujoco.sysid without its extra")
    except ImportError as error:
        raise Skip(f"{error}: pip install -e '.[mujoco]'") from None
    from identify_speed import mujoco_identify_inputs

    import jaxrot

    manoeuvres = mt.manoeuvres(noise_seed=0)
    if side == "sysid":
        return lambda: ms.sysid_fit(manoeuvres, fit_initial_state=True).inertia
    experiments, keywords = mujoco_identify_inputs(manoeuvres)  # built before the timed call, as before
    return lambda: jaxrot.identify(experiments, **keywords).inertia


def _fit_inertia():
    """The fitting notebook's problem (docs/examples/fit_inertia.ipynb)."""
    import jax
    import jax.numpy as jnp

    import jaxrot
    from jaxrot import quaternion as quat

    rot = quat.to_matrix(quat.exp(jnp.array([0.4, -0.7, 0.25])))
    true_inertia = rot @ jnp.diag(jnp.array([2.0, 3.0, 4.0])) @ rot.T

    def gravity(t, q, omega, args):
        return jnp.cross(quat.rotate(q, args["offset"]), args["weight"])

    args = {"offset": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.array([0.0, 0.0, -9.81])}
    state = jaxrot.RotState(quat.exp(jnp.array([0.1, 0.2, 0.3])), jnp.array([0.8, -0.5, 1.5]))
    ts = jnp.linspace(0.0, 6.0, 100)
    truth = jaxrot.reference_rollout(
        state, true_inertia, ts, torque=gravity, args=args, rtol=1e-10, atol=1e-10
    )
    noise = 1e-3 * jax.random.normal(jax.random.PRNGKey(0), (ts.shape[0], 3))
    observed = jaxrot.Trajectory(ts, quat.multiply(quat.exp(noise), truth.q), None)
    return lambda: jaxrot.fit_inertia(observed, torque=gravity, args=args).inertia


def _jax_md(method):
    """``benchmarks/jax_md_rigid.py``'s first-call problem: a jitted 1000-step loop of 40 interacting
    tetrahedra (dt 1/64, kT 1, gamma 10), jaxrot.jax_md's simulator or jax_md's own."""
    try:
        import jax_md_systems as systems
        from jax_md import rigid_body, simulate

        import jaxrot.jax_md as jm
    except ImportError:
        raise Skip(NO_JAX_MD) from None
    import jax

    energy_fn, shift, body = systems.tetrahedra(40)
    simulator = {"jaxrot": jm.nvt_langevin, "jax_md": simulate.nvt_langevin}[method]
    init_fn, apply_fn = simulator(energy_fn, shift, 1 / 64, 1.0, rigid_body.RigidBody(10.0, 10.0))
    state = init_fn(jax.random.key(3), body, mass=systems.shape().mass())

    def fn(state):
        return jax.lax.fori_loop(0, 1000, lambda i, s: apply_fn(s), state)

    jitted = jax.jit(fn)
    return fn, (state,), lambda: jitted(state)


def build(name):
    """``(fn, example)`` for a jitted entry (else None) and the user's call ``() -> result``."""
    builders = {
        "rollout_zhao": lambda: _heavy_top("forward", "zhao"),
        "rollout_rkmk4": lambda: _heavy_top("forward", "rkmk4"),
        "rollout_rkmk_dopri8": lambda: _heavy_top("forward", "rkmk_dopri8"),
        "diffrax_tsit5": lambda: _heavy_top("forward", "diffrax_tsit5"),
        "grad_zhao": lambda: _heavy_top("gradient", "zhao"),
        "grad_rkmk4": lambda: _heavy_top("gradient", "rkmk4"),
        "grad_diffrax_tsit5": lambda: _heavy_top("gradient", "diffrax_tsit5"),
        "rollout_exp_rk4_fluid": lambda: _fluid("exp_rk4"),
        "diffrax_tsit5_fluid": lambda: _fluid("diffrax_tsit5"),
        "rollout_baoab_thermal": _thermal,
        "solver_rkmk_dopri5": lambda: _diffeqsolve("rkmk_dopri5"),
        "diffeqsolve_tsit5": lambda: _diffeqsolve("tsit5"),
        "identify": lambda: (None, None, _satellite("identify")),
        "diffrax_optimistix": lambda: (None, None, _satellite("diffrax")),
        "identify_mujoco": lambda: (None, None, _mujoco("identify")),
        "mujoco_sysid": lambda: (None, None, _mujoco("sysid")),
        "fit_inertia": lambda: (None, None, _fit_inertia()),
        "jax_md_nvt_langevin_jaxrot": lambda: _jax_md("jaxrot"),
        "jax_md_nvt_langevin": lambda: _jax_md("jax_md"),
    }
    fn, example, call = builders[name]()
    return (None if fn is None else (fn, example)), call
