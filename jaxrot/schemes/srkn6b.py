"""Blanes–Moan SRKN₆ᵇ: an order-4 kick/rotor splitting with six torque calls per step."""

from typing import ClassVar

from ._rkn_splitting import AbstractRKNSplitting, palindrome


class SRKN6b(AbstractRKNSplitting):
    r"""Blanes & Moan's SRKN₆ᵇ over the exact free rotor: order 4, torques of ``(t, q)`` only.

    ``K(b₁) A(a₁) K(b₂) A(a₂) K(b₃) A(a₃) K(b₄) A(a₃) K(b₃) A(a₂) K(b₂) A(a₁) K(b₁)``:
    seven kicks ``L += b_i Δt τ`` (the last one's torque is reused by the next
    step's first, so six calls per step) and six exact torque-free rotations for
    ``a_i Δt``. A torque that depends on ω is refused with a `ValueError` (the kicks
    would no longer be exact and the order would drop); torque-free, it is exact.

    Reference:
        S. Blanes and P. C. Moan, "Practical symplectic partitioned Runge–Kutta and
        Runge–Kutta–Nyström methods", J. Comput. Appl. Math. 142, 313–330 (2002),
        table 3; coefficients as in Principia's ``integrators/methods.hpp``.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> from jaxrot import torques
        >>> scene = jaxrot.SCENES["heavy_top"]()
        >>> traj = jaxrot.rollout("srkn6b", scene.state, scene.inertia, 0.05, 20, torque=scene.torque,
        ...                       args=scene.args)
        >>> print(traj.q.shape, jaxrot.SCHEMES["srkn6b"].torque_evals_per_step)
        (21, 4) 6
    """

    name: ClassVar[str] = "srkn6b"
    order: ClassVar[int] = 4
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    kick_weights: ClassVar[tuple[float, ...]] = palindrome(
        (0.082984406417405200, 0.39630980149836800, -0.039056304922348600),
        (1 - 2 * (0.082984406417405200 + 0.39630980149836800 - 0.039056304922348600),),  # 0.1195241940131508
    )
    rotor_weights: ClassVar[tuple[float, ...]] = palindrome(
        (0.24529895718427100, 0.60487266571108000, 0.5 - 0.24529895718427100 - 0.60487266571108000)
    )  # a₃ = −0.350171622895351
