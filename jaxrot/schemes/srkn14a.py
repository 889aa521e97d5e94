"""Blanes–Moan SRKN₁₄ᵃ: an order-6 kick/rotor splitting with fourteen torque calls per step."""

from typing import ClassVar

from ._rkn_splitting import AbstractRKNSplitting, palindrome


_ROTORS = (
    0.037859319840611600,
    0.10263563310243500,
    -0.025867888266558700,
    0.31424140307144700,
    -0.13014445951741500,
    0.10641770036954300,
    -0.0087942431285105800,
)
_KICKS = (
    0.091719152624461650,
    0.18398317000500600,
    -0.056534365832888270,
    0.0049146887747128540,
    0.14376112716835800,
    0.32856769374680400,
)


class SRKN14a(AbstractRKNSplitting):
    r"""Blanes & Moan's SRKN₁₄ᵃ over the exact free rotor: order 6, torques of ``(t, q)`` only.

    ``A(a₁) K(b₁) A(a₂) … K(b₇) A(a₈) K(b₇) … K(b₁) A(a₁)``: fifteen exact torque-free
    rotations and fourteen kicks (torque calls) per step. A torque that depends on
    ω is refused with a `ValueError`; torque-free, it is exact.

    Reference:
        S. Blanes and P. C. Moan, J. Comput. Appl. Math. 142, 313–330 (2002), table 3;
        the same method drives a torqued body in ACM TOMS Algorithm 903 (Celledoni,
        Fassò, Säfström and Zanna).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> scene = jaxrot.SCENES["heavy_top"]()
        >>> traj = jaxrot.rollout("srkn14a", scene.state, scene.inertia, 0.1, 10, torque=scene.torque,
        ...                       args=scene.args)
        >>> print(traj.q.shape, jaxrot.SCHEMES["srkn14a"].torque_evals_per_step)
        (11, 4) 14
    """

    name: ClassVar[str] = "srkn14a"
    order: ClassVar[int] = 6
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    rotor_weights: ClassVar[tuple[float, ...]] = palindrome(
        _ROTORS, (1 - 2 * sum(_ROTORS),)
    )  # 0.2073050690568954
    kick_weights: ClassVar[tuple[float, ...]] = palindrome(
        _KICKS + (0.5 - sum(_KICKS),)
    )  # b₇ = −0.19641146648645423
