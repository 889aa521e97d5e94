"""One process of tests/test_multiprocess.py's two-process run (and the scene the test compares).

``python tests/_multiprocess_worker.py PORT PROCESS_ID OUT_DIR`` joins a 2-process
`jax.distributed` run on 127.0.0.1:PORT with 2 CPU devices of its own, builds the
global state from its own bodies, runs the rollout on a mesh over all 4 devices,
gathers the trajectory and saves ``t``/``q``/``omega`` to ``OUT_DIR/process<i>.npz``.
Importing it (the test, pytest's collection) runs nothing.
"""

import sys

import jax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat


N_PROCESSES = 2
DEVICES_PER_PROCESS = 2
N_BODIES = 8  # 2 per device
INERTIA = np.array([1.0, 2.0, 3.0])
DT = 1e-2
N_STEPS = 100
SAVE_EVERY = 10
# A heavy top: the centre of mass at R in the body frame, weight G in the world frame.
ARGS = {"r": np.array([0.0, 0.0, 0.5]), "g": np.array([0.0, 0.0, -9.81])}
COLLECTIVES = ("all-gather", "all-reduce", "all-to-all", "collective-permute", "reduce-scatter")


def gravity(t, q, omega, args):
    return jnp.cross(quat.rotate(q, args["r"]), args["g"])


def scene():
    """``(q, omega)`` of all bodies, float64 numpy: random orientations and angular velocities."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(N_BODIES, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q, rng.normal(size=(N_BODIES, 3))


def run(state):
    """The rollout both sides compute (under ``jit``: eager value checks would read every body)."""
    return jaxrot.rollout(
        "zhao", state, INERTIA, DT, N_STEPS, torque=gravity, args=ARGS, save_every=SAVE_EVERY
    )


def main(port: int, process_id: int, out_dir: str):
    jax.config.update("jax_platforms", "cpu")
    jax.config.update("jax_num_cpu_devices", DEVICES_PER_PROCESS)
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.config.update("jax_enable_x64", True)
    jax.distributed.initialize(
        coordinator_address=f"127.0.0.1:{port}",
        num_processes=N_PROCESSES,
        process_id=process_id,
        cluster_detection_method="deactivate",  # the arguments above, not SLURM/Open MPI variables
        initialization_timeout=120,
    )
    from jax.experimental import multihost_utils
    from jax.sharding import NamedSharding, PartitionSpec as P

    assert jax.process_count() == N_PROCESSES and jax.local_device_count() == DEVICES_PER_PROCESS
    mesh = jax.make_mesh((jax.device_count(),), ("p",))  # all devices of both processes
    bodies = NamedSharding(mesh, P("p"))
    # This process's own bodies: the rows its devices hold, in order (one contiguous block).
    rows = sorted(
        (i[0].start, i[0].stop) for i in bodies.addressable_devices_indices_map((N_BODIES, 4)).values()
    )
    assert all(a[1] == b[0] for a, b in zip(rows, rows[1:], strict=False)), rows
    mine = slice(rows[0][0], rows[-1][1])
    q, omega = scene()
    state = jaxrot.RotState(
        jax.make_array_from_process_local_data(bodies, q[mine]),
        jax.make_array_from_process_local_data(bodies, omega[mine]),
    )
    assert state.q.shape == (N_BODIES, 4) and not state.q.is_fully_addressable
    compiled = jax.jit(run).lower(state).compile()
    # Per-body torque: no body needs another's data, so the compiled program communicates nothing.
    assert not [c for c in COLLECTIVES if c in compiled.as_text()]
    traj = compiled(state)
    assert traj.q.sharding.is_equivalent_to(NamedSharding(mesh, P(None, "p")), 3), traj.q.sharding
    gathered = {name: multihost_utils.process_allgather(x, tiled=True) for name, x in traj._asdict().items()}
    # Each process's own shards are its rows of the gathered trajectory.
    for shard in traj.q.addressable_shards:
        np.testing.assert_array_equal(np.asarray(shard.data), gathered["q"][shard.index])
    np.savez(f"{out_dir}/process{process_id}.npz", **gathered)
    jax.distributed.shutdown()


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])
