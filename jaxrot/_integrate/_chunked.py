"""Long rollouts in chunks: progress between chunks, checkpoints to disk, resumption.

`rollout_chunks` runs the same compiled time loop as `jaxrot.rollout`, a chunk of
steps at a time, handing the scheme's carry (not just the state: ``"rozmanov"`` and
``"no_squish"`` carry a torque or a momentum) from one chunk to the next. Times and
step numbers come from the global integer step index, so the chunks concatenated
along axis 0 are bit for bit the one-call trajectory, and a run saved with
`save_checkpoint`, loaded with `load_checkpoint` and resumed gives the same bits
too. Chunks of one size share one compilation (the step offset is traced), so a run
compiles at most three programs: the initial carry, full chunks, and a shorter last
chunk.
"""

import dataclasses
import math
import os
import tempfile
from collections.abc import Iterator
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._core._concrete import is_concrete
from .._particles import unflatten_trajectory
from .._state import RotState, Trajectory
from .._validation import check_count
from ._run import Run, prepare_run


# Bumped when the file layout changes, so that an old file is rejected with a clear message.
_FORMAT = 1
_META = ("scheme", "step", "dt", "t0", "save_every", "n_steps", "dtype", "batch_shape")


class Checkpoint(NamedTuple):
    """Where a chunked rollout stands after a chunk: enough to resume it exactly.

    Attributes:
        carry: the scheme's carry with the particle axes flattened to one, as
            ``rollout(..., return_carry=True)`` gives it (e.g. a `RotState` of
            ``(N, 4)`` and ``(N, 3)`` arrays). After `load_checkpoint` it is the
            tuple of its leaves; `rollout_chunks` rebuilds the structure.
        step: steps done (a multiple of ``save_every``).
        scheme: the scheme's name.
        dt: the time step, as a Python float (exact in the run's dtype).
        t0: the initial time of the run, as a Python float.
        save_every: steps between saved states.
        n_steps: the run's total number of steps.
        dtype: the run's float dtype name, ``"float64"`` or ``"float32"``.
        batch_shape: the particle axes of ``state``, a tuple of ints.
    """

    carry: Any
    step: int
    scheme: str
    dt: float
    t0: float
    save_every: int
    n_steps: int
    dtype: str
    batch_shape: tuple


def _check_chunk_steps(chunk_steps, save_every):
    chunk_steps = check_count(chunk_steps, "chunk_steps", 1)
    if chunk_steps % save_every:
        lower = max(save_every, chunk_steps // save_every * save_every)
        raise ValueError(
            f"`chunk_steps` must be a positive multiple of `save_every` (= {save_every}), so that chunks "
            f"end on saved steps; got {chunk_steps}. Use {lower} or {lower + save_every}."
        )
    return chunk_steps


def _scalar(x):
    """A concrete 0-d array as a Python float (exact: float64 holds any float32); else as is."""
    return float(np.asarray(x)) if is_concrete(x) else x


def _metadata(run: Run) -> dict:
    # Checked in this order: a dtype mismatch is named as such, not as the dt it rounds.
    return {
        "scheme": run.scheme.name,
        "dtype": np.dtype(run.dt.dtype).name,
        "batch_shape": run.batch_shape,
        "save_every": run.save_every,
        "n_steps": run.n_steps,
        "dt": _scalar(run.dt),
        "t0": _scalar(run.t0),
    }


def _resume_carry(run: Run, checkpoint) -> tuple[Any, int]:
    """The checkpoint's carry, rebuilt and checked against this run; and its step."""
    if not isinstance(checkpoint, Checkpoint):
        raise ValueError(
            f"`resume` must be a jaxrot.Checkpoint (from rollout_chunks or load_checkpoint); "
            f"got {type(checkpoint).__name__}."
        )
    for field, ours in _metadata(run).items():
        theirs = getattr(checkpoint, field)
        if field == "batch_shape":
            theirs = tuple(int(n) for n in theirs)
        if is_concrete(theirs, ours) and theirs != ours:
            raise ValueError(
                f"`resume`: the checkpoint's `{field}` is {theirs!r} but this run's is {ours!r}. Resume "
                "with the same scheme, dt, t0, save_every, n_steps, dtype and particle axes as the saved run."
            )
    step = checkpoint.step
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)):
        raise ValueError(f"`resume`: the checkpoint's `step` must be an int; got {type(step).__name__}.")
    if step < 0 or step % run.save_every or step > run.n_saves * run.save_every:
        raise ValueError(
            f"`resume`: the checkpoint's `step` ({step}) must be a multiple of save_every ({run.save_every}) "
            f"between 0 and {run.n_saves * run.save_every}."
        )
    # The structure the scheme's init builds, traced abstractly (nothing is computed).
    unchecked = dataclasses.replace(run, runtime_check=False)
    expected = jax.eval_shape(lambda: unchecked.flat(0, state=run.flat_state)[1])
    wanted, treedef = jax.tree_util.tree_flatten(expected)
    leaves = jax.tree_util.tree_leaves(checkpoint.carry)
    found = [(tuple(np.shape(x)), np.dtype(x.dtype).name) for x in leaves]
    if found != [(tuple(x.shape), np.dtype(x.dtype).name) for x in wanted]:
        raise ValueError(
            f"`resume`: the checkpoint's `carry` (leaves {found}) does not match the carry of scheme "
            f"{run.scheme.name!r} for these particles ({[(x.shape, x.dtype.name) for x in wanted]}). "
            "Was it saved by a differently configured scheme?"
        )
    return treedef.unflatten([jnp.asarray(x) for x in leaves]), int(step)


def _concatenated(trajectories) -> Trajectory:
    """Flat trajectory chunks joined along the saved-state axis."""
    return Trajectory(*(jnp.concatenate(parts) for parts in zip(*trajectories, strict=True)))


def _generate(run: Run, chunk_steps: int, start, *, warn: bool) -> Iterator[tuple[Trajectory, Checkpoint]]:
    """The chunks from the beginning (``start=None``) or from ``start = (carry, step)``."""
    chunk_saves = chunk_steps // run.save_every
    metadata = _metadata(run)
    offset_dtype = jnp.arange(0).dtype
    first = None
    if start is not None:
        carry, step = start
        saves_done = step // run.save_every
    else:
        # One chunk is one call (the same program); else the call with no steps gives the initial
        # carry and saved state, and the chunks continue from there.
        n = run.n_saves if run.n_saves <= chunk_saves else 0
        first, carry = run.flat(n, state=run.flat_state)
        carry = run.checked(carry)
        saves_done = n
    while saves_done < run.n_saves or first is not None:
        n = min(chunk_saves, run.n_saves - saves_done)
        if n > 0:
            traj, carry = run.flat(n, carry=carry, save_offset=jnp.asarray(saves_done, offset_dtype))
            carry = run.checked(carry)
            if first is not None:
                traj = _concatenated([first, traj])
        else:
            traj = first
        first = None
        saves_done += n
        if warn and saves_done == run.n_saves:
            run.warn_if_reported(run.scheme.summarize(carry), stacklevel=2)
        checkpoint = Checkpoint(carry, saves_done * run.save_every, **metadata)
        traj = unflatten_trajectory(traj, run.batch_shape)
        run.raise_if_nonfinite(traj, "jaxrot.rollout_chunks", saves_done + 1 - traj.t.shape[0])
        yield traj, checkpoint


def rollout_chunks(
    scheme,
    state: RotState,
    inertia,
    dt,
    n_steps: int,
    *,
    chunk_steps: int,
    torque=None,
    args=None,
    save_every: int = 1,
    t0=0.0,
    drive=None,
    normalize: bool = False,
    resume: Checkpoint | None = None,
    runtime_check: bool = False,
    check_finite: bool = True,
    fluid=None,
    key=None,
) -> Iterator[tuple[Trajectory, Checkpoint]]:
    """`jaxrot.rollout` a chunk of steps at a time: yields ``(trajectory_chunk, checkpoint)``.

    The arguments are those of `jaxrot.rollout`. The chunks concatenated along
    axis 0 equal ``rollout(...)`` with the same arguments, bit for bit: the first
    chunk holds the initial state (index 0) and the states saved in its first
    ``chunk_steps`` steps, each later chunk the states saved in its steps only,
    and the last chunk may be shorter. As there, ``save_every`` must divide
    ``n_steps``, so that the last chunk ends on the final state. Nothing runs
    until the first chunk is asked for; the arguments are checked at the call.

    Args:
        chunk_steps: steps per chunk, a positive multiple of ``save_every``.
        resume: a `Checkpoint` of an earlier run with the same arguments (from
            this generator or `load_checkpoint`): continue after its step. Its
            scheme name, ``dt``, ``t0``, ``save_every``, ``n_steps``, dtype and
            particle axes must match this call's; the torque, ``args``, drive and
            inertia cannot be checked: pass the same ones.
        runtime_check: as in `jaxrot.rollout`, with global step numbers; an eager
            run raises `jaxrot.IntegrationError` after the first chunk in which a
            step went bad (its message counts the particles affected so far).
        check_finite: as in `jaxrot.rollout`, per chunk: an eager run raises
            `jaxrot.IntegrationError` at the first chunk with a NaN or an infinity
            (saved state numbers within that chunk; its times are global).
        fluid, key: as in `jaxrot.rollout`; pass the same ones to resume.

    Yields:
        ``(trajectory_chunk, checkpoint)``: a `Trajectory` with ``t`` ``(k,)``,
        ``q`` ``(k, ..., 4)``, ``omega`` ``(k, ..., 3)`` (particle axes restored),
        and the `Checkpoint` after the chunk (carry with particle axes flattened).
        A resumed run whose checkpoint is at the end yields nothing.

    Warns:
        RuntimeWarning: as `jaxrot.rollout`, from the final carry, with the last chunk.

    Raises:
        ValueError: as `jaxrot.rollout` (a ``save_every`` that does not divide
            ``n_steps`` included); for a ``chunk_steps`` that is not a
            positive multiple of ``save_every``; for a ``resume`` checkpoint
            whose settings differ (the message names the field). All before
            anything compiles.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> inertia = jnp.array([1.0, 2.0, 3.0])
        >>> chunks = [c for c, _ in jaxrot.rollout_chunks("zhao", s, inertia, 0.01, 100, chunk_steps=40)]
        >>> [c.q.shape[0] for c in chunks]  # the initial state + 40, then 40, then 20
        [41, 40, 20]
        >>> whole = jaxrot.rollout("zhao", s, inertia, 0.01, 100)
        >>> bool(jnp.all(jnp.concatenate([c.q for c in chunks]) == whole.q))
        True
    """
    run = prepare_run(
        scheme,
        state,
        inertia,
        dt,
        n_steps,
        torque,
        args,
        save_every,
        t0,
        drive,
        normalize,
        runtime_check,
        check_finite,
        fluid,
        key,
    )
    chunk_steps = _check_chunk_steps(chunk_steps, run.save_every)
    # A mismatched checkpoint is rejected now, not at the first chunk.
    start = None if resume is None else _resume_carry(run, resume)
    return _generate(run, chunk_steps, start, warn=True)


def default_chunk_steps(n_steps: int, save_every: int) -> int:
    """About 100 chunks, each a whole number of saves (at least one)."""
    return max(1, math.ceil((n_steps // save_every) / 100)) * save_every


def chunked_rollout(run: Run, chunk_steps: int | None, *, progress: bool, return_carry: bool):
    """`jaxrot.rollout` with ``progress`` or ``chunk_steps``: the chunks of ``run``, concatenated."""
    from tqdm import tqdm

    if chunk_steps is None:
        chunk_steps = default_chunk_steps(run.n_steps, run.save_every)
    chunk_steps = _check_chunk_steps(chunk_steps, run.save_every)
    chunks, carry = [], None
    bar = tqdm(
        total=run.n_saves * run.save_every,
        desc=f"rollout {run.scheme.name}",
        unit="step",
        disable=not progress,
    )
    with bar:
        for traj, checkpoint in _generate(run, chunk_steps, None, warn=False):
            chunks.append(traj)
            carry = checkpoint.carry
            bar.update(checkpoint.step - bar.n)
    traj = _concatenated(chunks)
    # stacklevel: through `rollout` and `particle_sharded`'s wrapper to the caller.
    run.warn_if_reported(run.scheme.summarize(carry), stacklevel=4)
    return (traj, carry) if return_carry else traj


def save_checkpoint(path, checkpoint: Checkpoint) -> str:
    """Write a `Checkpoint` to one ``.npz`` file (numpy arrays only, no pickle); returns its path.

    ``.npz`` is appended to ``path`` if missing, as `numpy.savez` does. The file
    is written next to its destination and renamed over it, so an interrupted
    save leaves the previous checkpoint intact.

    Example:
        >>> import os, tempfile, jax, jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> _, ckpt = next(jaxrot.rollout_chunks("no_squish", s, jnp.array([1.0, 2, 3]), 0.01, 100,
        ...                                      chunk_steps=50))
        >>> path = jaxrot.save_checkpoint(os.path.join(tempfile.mkdtemp(), "run"), ckpt)
        >>> loaded = jaxrot.load_checkpoint(path)
        >>> loaded.step, loaded.scheme, len(loaded.carry) == len(jax.tree_util.tree_leaves(ckpt.carry))
        (50, 'no_squish', True)
    """
    if not isinstance(checkpoint, Checkpoint):
        raise ValueError(f"`checkpoint` must be a jaxrot.Checkpoint; got {type(checkpoint).__name__}.")
    if not is_concrete(checkpoint.carry, checkpoint.dt, checkpoint.t0):
        raise ValueError("`checkpoint` holds traced values (inside jit?); save it from an eager run.")
    path = os.fspath(path)
    if not path.endswith(".npz"):
        path += ".npz"
    leaves = jax.tree_util.tree_leaves(checkpoint.carry)
    arrays = {f"carry_{i}": np.asarray(x) for i, x in enumerate(leaves)}
    arrays.update(
        format=np.asarray(_FORMAT),
        n_leaves=np.asarray(len(leaves)),
        scheme=np.asarray(checkpoint.scheme),
        step=np.asarray(int(checkpoint.step)),
        dt=np.asarray(float(checkpoint.dt), np.float64),
        t0=np.asarray(float(checkpoint.t0), np.float64),
        save_every=np.asarray(int(checkpoint.save_every)),
        n_steps=np.asarray(int(checkpoint.n_steps)),
        dtype=np.asarray(checkpoint.dtype),
        batch_shape=np.asarray(checkpoint.batch_shape, dtype=np.int64).reshape(-1),
    )
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".checkpoint-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return path


def load_checkpoint(path) -> Checkpoint:
    """Read a `Checkpoint` written by `save_checkpoint` (``allow_pickle=False``).

    The carry comes back as the tuple of its leaves (numpy arrays);
    ``rollout_chunks(..., resume=checkpoint)`` rebuilds the scheme's carry from
    them and checks their shapes and dtypes. See `save_checkpoint` for an example.
    """
    with np.load(os.fspath(path), allow_pickle=False) as data:
        missing = [key for key in ("format", "n_leaves", *_META) if key not in data.files]
        if missing:
            raise ValueError(f"{os.fspath(path)!r} is not a jaxrot checkpoint: it lacks {missing}.")
        if int(data["format"]) != _FORMAT:
            raise ValueError(
                f"{os.fspath(path)!r} is a jaxrot checkpoint of format {int(data['format'])}; "
                f"this version reads format {_FORMAT}."
            )
        carry = tuple(np.array(data[f"carry_{i}"]) for i in range(int(data["n_leaves"])))
        return Checkpoint(
            carry=carry,
            step=int(data["step"]),
            scheme=str(data["scheme"]),
            dt=float(data["dt"]),
            t0=float(data["t0"]),
            save_every=int(data["save_every"]),
            n_steps=int(data["n_steps"]),
            dtype=str(data["dtype"]),
            batch_shape=tuple(int(n) for n in data["batch_shape"]),
        )
