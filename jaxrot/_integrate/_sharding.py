"""Particle axes sharded over a device mesh: `rollout` keeps the layout and communicates nothing.

`rollout` flattens the particle axes to one, ``vmap``-s the bodies over it inside a
``lax.scan`` over time, and concatenates the initial state in front of the saved
ones. Given a ``state`` whose particle axes are sharded with a `NamedSharding`:

- On a mesh whose axes are ``Auto`` (``jax.sharding.Mesh``'s default), XLA's sharding
  propagation alone keeps a 1-D particle batch sharded through all of that, with no
  collective for per-body torques, per-body ``args`` or per-particle inertia, and the
  result comes back as ``P(None, "p")`` (jax 0.10.2 and 0.12). It does not when the
  flattening mixes devices' rows: a batch ``(A, B)`` sharded on ``B`` (or on both
  axes with more than one row of ``A`` per device) made XLA replicate the time loop
  and all-gather the state every saved step.
- On a mesh whose axes are ``Explicit`` (``jax.make_mesh``'s default in both versions)
  the sharding is part of each array's type, and the schemes' code, written for
  unsharded bodies, fails to trace (``vmap`` of mixed shardings).

So `particle_sharded` (around `rollout` and `reference_rollout`) runs the call on the
same devices with every mesh axis ``Auto`` (a zero-copy ``device_put`` for concrete
arrays; ``jax.sharding.auto_axes`` under ``jit``), and pins the results: ``q`` and
``omega`` ``(n_saved, *batch, 4 / 3)`` to ``P(None, *particle_spec)``, ``t`` replicated,
a returned carry's ``(N, ...)`` leaves to the flattened particle spec; then gives them
back on the caller's mesh. Inside `rollout`, `shard_particles` pins the flattened
``(N, ...)`` inputs to the particle axes' mesh axes, major first. When the flattening
keeps each device's bodies contiguous (the particle axes after the first one split
into blocks of more than one row are unsharded; always for one particle axis) this
moves nothing; otherwise it costs one re-layout of the state at the start and of the
trajectory at the end, and still none per step.

A coupled torque (`jaxrot.torques.DipoleInteraction`) gathers the other bodies over
the ``vmap`` axis; under sharding XLA turns that into an all-gather across devices,
so it stays right and communicates. Sharding needs the sharded axes to divide
evenly: JAX refuses a `NamedSharding` that does not (`device_put` raises), so pad the
batch. Under your own ``jit`` on an ``Auto`` mesh the tracers carry no sharding:
``jit`` takes it from the arguments and propagation does the rest, unpinned.
"""

import contextlib
import contextvars
import functools
import inspect
import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
from jax.sharding import AxisType, Mesh, NamedSharding, PartitionSpec

from .._state import Trajectory


class ParticleLayout(NamedTuple):
    """The particle axes of one call, laid out over a device mesh.

    Attributes:
        mesh: the mesh the call computes on, with every axis ``Auto``: a
            `jax.sharding.Mesh`, or under ``jit`` the context's abstract mesh.
        batch_spec: one `PartitionSpec` entry per particle axis.
    """

    mesh: Any
    batch_spec: tuple

    @property
    def flat_entry(self):
        """The spec entry of the flattened ``(N,)`` particle axis: the particle axes' mesh axes, major
        first."""
        names = tuple(name for entry in self.batch_spec for name in _axis_names(entry))
        if not names:
            return None
        return names[0] if len(names) == 1 else names

    def sharding(self, *entries) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec(*entries))


# The layout of the `particle_sharded` call in progress (None: unsharded), for `shard_particles`:
# under `jit` the tracers inside the call no longer show it.
_LAYOUT: contextvars.ContextVar[ParticleLayout | None] = contextvars.ContextVar("jaxrot_layout", default=None)


@contextlib.contextmanager
def _current(layout):
    token = _LAYOUT.set(layout)
    try:
        yield
    finally:
        _LAYOUT.reset(token)


def _axis_names(entry) -> tuple:
    if isinstance(entry, str):
        return (entry,)
    if isinstance(entry, tuple):
        return entry
    return ()  # None (or UNCONSTRAINED): no mesh axis


def _named_sharding(x):
    """The `NamedSharding` of a concrete array, or the one in a tracer's type (explicit axes); else None."""
    if isinstance(x, jax.core.Tracer):
        sharding = getattr(jax.typeof(x), "sharding", None)
        # A type shows only Explicit axes; with none, it says nothing about the layout.
        if not isinstance(sharding, NamedSharding) or AxisType.Explicit not in tuple(
            sharding.mesh.axis_types
        ):
            return None
    elif isinstance(x, jax.Array):
        sharding = x.sharding
    else:
        return None
    if not isinstance(sharding, NamedSharding) or sharding.mesh.empty:
        return None
    if AxisType.Manual in tuple(sharding.mesh.axis_types):
        return None  # inside `shard_map`: each device sees its own bodies
    return sharding


def _auto_mesh(mesh: Mesh) -> Mesh:
    """The same devices and axis names, every axis ``Auto``."""
    return Mesh(mesh.devices, mesh.axis_names, axis_types=(AxisType.Auto,) * len(mesh.axis_names))


def output_shardings(out, layout: ParticleLayout, n: int):
    """A tree of `NamedSharding` matching ``out`` (a `Trajectory`, or a tuple holding one and a carry).

    Trajectories: ``t`` replicated, ``q``/``omega`` ``(n_saved, *batch, k)`` as
    ``P(None, *batch_spec)``. Other leaves: ``(n, ...)`` on the flattened particle
    axis, anything else replicated.
    """

    def one(x):
        if isinstance(x, Trajectory):
            particles = layout.sharding(None, *layout.batch_spec)
            return Trajectory(layout.sharding(), particles, particles)
        if len(x.shape) >= 1 and x.shape[0] == n:
            return layout.sharding(layout.flat_entry)
        return layout.sharding()

    return jax.tree_util.tree_map(one, out, is_leaf=lambda x: isinstance(x, Trajectory))


def _constrain(out, shardings):
    return jax.tree_util.tree_map(jax.lax.with_sharding_constraint, out, shardings)


def shard_particles(values, in_axes):
    """Pin the flattened particle axis of ``values`` to the layout of the current call.

    ``in_axes`` is a prefix tree of ``values`` as for `jax.vmap`: ``0`` where the
    leading axis is the ``(N,)`` particle axis, None where shared. Outside a
    sharded call it returns ``values`` unchanged.
    """
    layout = _LAYOUT.get()
    if layout is None:
        return values
    flat = layout.sharding(layout.flat_entry)

    def one(axis, subtree):
        if axis is None:
            return subtree
        return jax.tree_util.tree_map(lambda x: jax.lax.with_sharding_constraint(x, flat), subtree)

    return jax.tree_util.tree_map(one, in_axes, values, is_leaf=lambda x: x is None)


def particle_shards() -> int:
    """How many shards the flattened particle axis of the current call is split into (1: unsharded)."""
    layout = _LAYOUT.get()
    if layout is None:
        return 1
    sizes = dict(zip(layout.mesh.axis_names, layout.mesh.axis_sizes, strict=True))
    return math.prod(sizes[name] for entry in layout.batch_spec for name in _axis_names(entry))


def particle_sharded(fn):
    """Make ``fn(..., state, ...)`` (`rollout`, `reference_rollout`) keep a sharded ``state``'s layout.

    ``state.q`` ``(*batch, 4)`` with a `NamedSharding` decides the layout; every
    array argument on that mesh is computed on its ``Auto`` twin (see the module
    docstring) and the results are pinned by `output_shardings` and returned on
    the caller's mesh. Anything else calls ``fn`` unchanged.
    """
    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        state = signature.bind(*args, **kwargs).arguments.get("state")
        q = state[0] if isinstance(state, tuple) and len(state) == 2 else None
        sharding = _named_sharding(q)
        if sharding is None:
            with _current(None):
                return fn(*args, **kwargs)
        batch_ndim = q.ndim - 1
        spec = tuple(sharding.spec) + (None,) * (q.ndim - len(sharding.spec))
        batch_spec = spec[:batch_ndim]
        n = math.prod(q.shape[:batch_ndim])
        mesh = sharding.mesh
        if AxisType.Explicit not in tuple(mesh.axis_types):
            layout = ParticleLayout(mesh, batch_spec)
            with _current(layout):
                out = fn(*args, **kwargs)
            return _constrain(out, output_shardings(out, layout, n))
        if not isinstance(q, jax.core.Tracer):
            return _eager_on_auto_axes(fn, mesh, batch_spec, n, args, kwargs)
        return _traced_on_auto_axes(fn, mesh, batch_spec, n, args, kwargs)

    return wrapper


def _eager_on_auto_axes(fn, mesh: Mesh, batch_spec, n, args, kwargs):
    """Concrete arrays on an explicit mesh: move them to its ``Auto`` twin (no copy) and back."""
    twin = _auto_mesh(mesh)

    def move(x, src, dst):
        if isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer):
            s = x.sharding
            if isinstance(s, NamedSharding) and s.mesh == src:
                return jax.device_put(x, NamedSharding(dst, s.spec))
        return x

    args, kwargs = jax.tree_util.tree_map(lambda x: move(x, mesh, twin), (args, kwargs))
    layout = ParticleLayout(twin, batch_spec)
    with _current(layout):
        out = fn(*args, **kwargs)
    out = _constrain(out, output_shardings(out, layout, n))
    return jax.tree_util.tree_map(lambda x: move(x, twin, mesh), out)


def _traced_on_auto_axes(fn, mesh, batch_spec, n, args, kwargs):
    """Tracers typed with explicit axes: run ``fn`` under `jax.sharding.auto_axes`."""
    arrays, static = eqx.partition((args, kwargs), lambda x: isinstance(x, jax.Array))

    def inner(arrays):
        a, k = eqx.combine(arrays, static)
        layout = ParticleLayout(jax.sharding.get_abstract_mesh(), batch_spec)
        with _current(layout):
            out = fn(*a, **k)
        return _constrain(out, output_shardings(out, layout, n))

    # `auto_axes` wants the output shardings up front; the output's structure (a carry?) from a trace.
    shape = jax.eval_shape(
        lambda: jax.sharding.auto_axes(inner, out_sharding=NamedSharding(mesh, PartitionSpec()))(arrays)
    )
    out_sharding = output_shardings(shape, ParticleLayout(mesh, batch_spec), n)
    return jax.sharding.auto_axes(inner, out_sharding=out_sharding)(arrays)
