"""A run across two processes (`jax.distributed` on 127.0.0.1, gloo) equals the single-process run.

The multi-host recipe of docs/performance.md on one machine: two Python processes with 2 CPU devices each
join one run, build the global state from their own bodies, roll out on a mesh over all 4
devices and gather the trajectory (tests/_multiprocess_worker.py); this process computes the
same rollout unsharded on one device.
"""

import os
import pathlib
import socket
import subprocess
import sys
import time

import jax
import numpy as np
import pytest
from _multiprocess_worker import N_PROCESSES, run, scene

import jaxrot


WORKER = pathlib.Path(__file__).with_name("_multiprocess_worker.py")
TIMEOUT_S = 300  # both processes together; a stuck rendezvous or collective cannot hang the suite


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def worker_env() -> dict:
    env = dict(os.environ)
    # The workers set their own device count (2 each, `jax_num_cpu_devices`); conftest.py's 4 fake
    # devices go. Every other XLA flag stays: the compiled code, hence the bits compared below, depends
    # on them (measured: --xla_backend_optimization_level=0 on one side only moved omega by 5e-15).
    flags = env.get("XLA_FLAGS", "").split()
    env["XLA_FLAGS"] = " ".join(f for f in flags if not f.startswith("--xla_force_host_platform_device"))
    env["JAX_PLATFORMS"] = "cpu"
    # gRPC (the coordinator) honours http(s)_proxy: keep loopback off any proxy.
    for key in ("no_proxy", "NO_PROXY"):
        env[key] = ",".join(filter(None, [env.get(key), "127.0.0.1", "localhost"]))
    return env


def run_workers(out: pathlib.Path):
    port, env = free_port(), worker_env()
    logs = [out / f"process{i}.log" for i in range(N_PROCESSES)]
    procs = []
    for i, log in enumerate(logs):
        with open(log, "w") as f:
            command = [sys.executable, str(WORKER), str(port), str(i), str(out)]
            procs.append(subprocess.Popen(command, stdout=f, stderr=subprocess.STDOUT, env=env))
    deadline = time.monotonic() + TIMEOUT_S
    try:
        # Until both are done; one failing (the other then waits on it) or the deadline stops both.
        while any(p.poll() is None for p in procs):
            if any(p.returncode for p in procs) or time.monotonic() > deadline:
                break
            time.sleep(0.2)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    report = "\n".join(
        f"--- process {i} (exit {p.returncode}):\n{logs[i].read_text()[-3000:]}" for i, p in enumerate(procs)
    )
    assert all(p.returncode == 0 for p in procs), f"timeout {TIMEOUT_S} s or a failed worker\n{report}"
    return [dict(np.load(out / f"process{i}.npz")) for i in range(N_PROCESSES)]


@pytest.mark.slow
def test_two_processes_equal_one(tmp_path):
    gathered = run_workers(tmp_path)
    q, omega = scene()
    one = jax.jit(run)(jaxrot.RotState(q, omega))  # one device of this process, unsharded
    for g in gathered:  # each process gathered the whole trajectory
        assert g["q"].shape == one.q.shape == (11, 8, 4) and g["q"].dtype == np.float64
        np.testing.assert_array_equal(g["t"], one.t)
        # The same bits for q and for omega, so no tolerance: each body's step is its own arithmetic,
        # the same operations in the same order whether a device holds 2 bodies or all 8. The program
        # sums nothing across bodies (a per-body torque: no collective; the cross-process traffic is the
        # gather, which copies), and both sides compile it under `jit` with the same XLA flags
        # (worker_env), so nothing is reassociated or fused differently. (tests/test_sharding.py's 8 ulp
        # cover other schemes' XLA rewrites; it reports none for "zhao".) A different program does move
        # bits: eager `rollout` here instead of `jit` moved omega by 1.6e-15, mismatched flags by 5e-15.
        np.testing.assert_array_equal(g["q"], one.q)
        np.testing.assert_array_equal(g["omega"], one.omega)
