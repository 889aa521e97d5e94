"""MuJoCo's side of `mujoco_free_body.py`: the model of n free bodies, and the ways to run it (one
model stepped in a loop, ``mujoco.rollout`` on it, and rollouts of one-body or grouped models on a
thread pool), their final orientations and their cost per body-step. Imports ``mujoco`` only when run."""

import os
import statistics
import sys
import time

import numpy as np


MOMENTS = (1.0, 2.0, 3.0)
INTEGRATORS = {"euler": "Euler", "implicit": "implicit", "implicitfast": "implicitfast", "rk4": "RK4"}


# Bodies per model of the ``rollout_groups`` path (and the error ladders): CPU time per body-step of
# 1000 bodies against the group size, measured under load (ratios): Euler 1342 ns (1 body), 369 (10),
# 288 (25), 268 (50); RK4 4678, 1321, 1080, 1019; implicit 2227, 1188, 1350, 1762 (its dense
# factorisation grows with the model). 20 sits near the floor of all three.
GROUP = 20


def model_xml(n, integrator, dt, joint="free"):
    """One MuJoCo model holding ``n`` bodies, each on its own joint, I = `MOMENTS`."""
    moments = " ".join(map(repr, MOMENTS))
    joint_xml = "<freejoint/>" if joint == "free" else '<joint type="ball"/>'
    body = f'<body>{joint_xml}<inertial pos="0 0 0" mass="1" diaginertia="{moments}"/></body>'
    return (
        f'<mujoco><option timestep="{dt!r}" integrator="{INTEGRATORS[integrator]}" gravity="0 0 0">'
        '<flag contact="disable" constraint="disable"/></option>'
        f"<worldbody>{body * n}</worldbody></mujoco>"
    )


def _set_state(model, data, q, omega_body, joint):
    mujoco = sys.modules["mujoco"]
    mujoco.mj_resetData(model, data)
    width_q, width_v = (7, 6) if joint == "free" else (4, 3)
    data.qpos.reshape(-1, width_q)[:, width_q - 4 :] = q
    data.qvel.reshape(-1, width_v)[:, width_v - 3 :] = omega_body


def _orientations(data, joint):
    width = 7 if joint == "free" else 4
    q = data.qpos.reshape(-1, width)[:, width - 4 :]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _group_size(n):
    """The largest divisor of ``n`` up to `GROUP`: every group model holds the same bodies."""
    return max(g for g in range(1, min(GROUP, n) + 1) if n % g == 0)


def _group_states(model, q, omega_body):
    """mjSTATE_FULLPHYSICS initial states ``(n / g, size)`` of the ``g``-body free-joint ``model``, one
    per group of ``g`` consecutive bodies (``g = 1``: one per body)."""
    import mujoco

    g = model.nbody - 1  # the world body is body 0
    data, spec = mujoco.MjData(model), mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = np.empty((len(q) // g, mujoco.mj_stateSize(model, spec)))
    for k, state in enumerate(states):
        _set_state(model, data, q[k * g : (k + 1) * g], omega_body[k * g : (k + 1) * g], "free")
        mujoco.mj_getState(model, data, state, spec)
    return states


def _group_orientations(final, g):
    """The bodies' unit orientations ``(n, 4)`` from final group states: time, then qpos (7 per body)."""
    q = final[:, 1 : 1 + 7 * g].reshape(-1, 7)[:, 3:7]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _chunks(n_steps, size=64):
    """Step counts of the rollout calls: ``mujoco.rollout`` records every state, so at most ``size``."""
    return [size] * (n_steps // size) + ([n_steps % size] if n_steps % size else [])


def _threaded(pool, single, datas, states, n_steps):
    for k in _chunks(n_steps):
        states = pool.rollout(single, datas, states, nstep=k)[0][:, -1]
    return states


def mujoco_final(integrator, q, omega_body, dt, n_steps):
    """MuJoCo's orientations after ``n_steps`` steps of ``dt``, or None where a body went unstable.

    One rollout per group of `_group_size` bodies on a thread pool (the ``rollout_groups`` path,
    whose orbits are those of the other paths to round-off: ``path_agreement_rad``). An unstable
    body makes MuJoCo warn (mjWARN_BADQACC) and reset its model to ``qpos0`` and time 0, whose
    identity orientations would pass for an answer ~π off: a final time short of ``n_steps·dt``
    marks it.
    """
    import mujoco
    from mujoco import rollout

    g = _group_size(len(q))
    group = mujoco.MjModel.from_xml_string(model_xml(g, integrator, dt))
    nthread = os.cpu_count() or 1
    with rollout.Rollout(nthread=nthread) as pool:
        datas = [mujoco.MjData(group) for _ in range(nthread)]
        final = _threaded(pool, group, datas, _group_states(group, q, omega_body), n_steps)
    if np.any(np.abs(final[:, 0] - n_steps * dt) > 1e-6 * n_steps * dt):
        return None
    return _group_orientations(final, g)


def _median_seconds(run, repeats):
    run()  # warm: allocations, page faults
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def mujoco_path_costs(q, omega_body, integrator, steps, repeats, joints, dt=1e-3):
    """Seconds per body-step of each way to run MuJoCo; and its paths' final q for a cross-check."""
    import mujoco
    from mujoco import rollout

    n = len(q)
    costs, finals = {}, {}
    for joint in joints:
        model = mujoco.MjModel.from_xml_string(model_xml(n, integrator, dt, joint))
        data = mujoco.MjData(model)

        def loop(model=model, data=data, joint=joint):
            _set_state(model, data, q, omega_body, joint)
            for _ in range(steps):
                mujoco.mj_step(model, data)

        name = "one_model" if joint == "free" else "one_model_ball"
        costs[name] = _median_seconds(loop, repeats) / (n * steps)
        finals[name] = _orientations(data, joint)
    # mujoco.rollout on the one model; states recorded in chunks of at most 64 steps (memory).
    model = mujoco.MjModel.from_xml_string(model_xml(n, integrator, dt))
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    _set_state(model, data, q, omega_body, "free")
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state0, spec)

    def one_model_rollout():
        state = state0
        for k in _chunks(steps):
            state = rollout.rollout(model, data, state, nstep=k)[0][0, -1]
        return state

    costs["rollout"] = _median_seconds(one_model_rollout, repeats) / (n * steps)
    q_rollout = one_model_rollout()[1 : 1 + 7 * n].reshape(n, 7)[:, 3:7]
    finals["rollout"] = q_rollout / np.linalg.norm(q_rollout, axis=1, keepdims=True)
    # n one-body rollouts, then n / g rollouts of g-body models, on a thread pool.
    nthread = os.cpu_count() or 1
    for name, g in (("rollout_threads", 1), ("rollout_groups", _group_size(n))):
        group = mujoco.MjModel.from_xml_string(model_xml(g, integrator, dt))
        states0 = _group_states(group, q, omega_body)
        with rollout.Rollout(nthread=nthread) as pool:
            datas = [mujoco.MjData(group) for _ in range(nthread)]

            def threaded(group=group, pool=pool, datas=datas, states0=states0):
                return _threaded(pool, group, datas, states0, steps)

            costs[name] = _median_seconds(threaded, repeats) / (n * steps)
            finals[name] = _group_orientations(threaded(), g)
    return costs, finals
