"""Every scheme of jaxrot, one per file, registered once by name; the registry and its views.

A scheme is a method, a model is what it integrates: each scheme declares ``models``, a frozenset of
``"vacuum"``, ``"fluid"``, ``"thermal"``, ``"overdamped"`` and ``"brownian"`` (`MODELS`), and
`schemes_for` lists those that integrate a model. `SCHEMES`, `FLUID_SCHEMES`, `THERMAL_SCHEMES`,
`OVERDAMPED_SCHEMES` and `BROWNIAN_SCHEMES` are its read-only views, one per model. Which call runs
which model, and whether a scheme fits it, is decided once by `jaxrot.rollout` and
`jaxrot.overdamped_rollout` (`jaxrot._integrate._bind`).

Example:
    >>> import jaxrot
    >>> sorted(jaxrot.schemes_for("thermal"))
    ['baoab', 'exp_euler']
    >>> sorted(jaxrot.SCHEMES["rkmk4"].models)
    ['overdamped', 'vacuum']
"""

from types import MappingProxyType

from ._base import AbstractScheme as AbstractScheme
from ._brownian import (
    AbstractBrownianScheme as AbstractBrownianScheme,
    BrownianEuler as BrownianEuler,
    BrownianSplitting as BrownianSplitting,
)
from ._exponential import (
    AbstractExponentialLieRK as AbstractExponentialLieRK,
    FluidCarry as FluidCarry,
)
from ._exponential_tableau import ExponentialTableau as ExponentialTableau
from ._langevin import AbstractLangevinScheme as AbstractLangevinScheme
from ._lie_runge_kutta import (
    AbstractLieRungeKutta as AbstractLieRungeKutta,
    LieRungeKuttaCarry as LieRungeKuttaCarry,
)
from ._overdamped import (
    AbstractOverdampedScheme as AbstractOverdampedScheme,
    LieEuler as LieEuler,
    LieMidpoint as LieMidpoint,
)
from ._rkn_splitting import AbstractRKNSplitting as AbstractRKNSplitting
from .baoab import BAOAB as BAOAB
from .euler import Euler as Euler
from .exp_euler import ExpEuler as ExpEuler
from .exp_midpoint import ExpMidpoint as ExpMidpoint
from .exp_rk4 import ExpRK4 as ExpRK4
from .exp_rk5 import ExpRK5 as ExpRK5
from .no_squish import NoSquish as NoSquish, NoSquishCarry as NoSquishCarry
from .rkmk4 import RKMK4 as RKMK4
from .rkmk_dopri5 import RKMKDopri5 as RKMKDopri5
from .rkmk_dopri8 import RKMKDopri8 as RKMKDopri8
from .rozmanov import Rozmanov as Rozmanov, RozmanovCarry as RozmanovCarry
from .splitting import Splitting as Splitting, SplittingCarry as SplittingCarry
from .srkn6b import SRKN6b as SRKN6b
from .srkn14a import SRKN14a as SRKN14a
from .zhao import Zhao as Zhao


# The models, by the call that runs them (`jaxrot._integrate._bind` describes each to a user).
MODELS = ("vacuum", "fluid", "thermal", "overdamped", "brownian")
# The models at a temperature: their schemes' ``order`` is a weak order (of ensemble averages).
THERMAL_MODELS = ("thermal", "brownian")

# The scheme classes a user may pass as an instance (the overdamped and Brownian ones advance the
# orientation alone, so they do not share `AbstractScheme`'s inertial step).
SCHEME_TYPES = (AbstractScheme, AbstractOverdampedScheme, AbstractBrownianScheme)


def _register(*schemes):
    registry = {}
    for scheme in schemes:
        if scheme.name in registry:
            raise ValueError(f"scheme name {scheme.name!r} is registered twice: one name means one scheme.")
        unknown = set(scheme.models) - set(MODELS)
        if not scheme.models or unknown:
            raise ValueError(
                f"scheme {scheme.name!r} declares models {sorted(scheme.models)}; known {MODELS}"
            )
        registry[scheme.name] = scheme
    return MappingProxyType(registry)


# Every scheme, once. The order is each view's order (results files and tables list them so).
REGISTRY = _register(
    Zhao(),
    Rozmanov(),
    Euler(),
    NoSquish(),
    Splitting(),
    LieEuler(),
    LieMidpoint(),
    RKMK4(),
    RKMKDopri5(),
    RKMKDopri8(),
    SRKN6b(),
    SRKN14a(),
    ExpMidpoint(),
    ExpRK4(),
    ExpRK5(),
    BAOAB(),
    ExpEuler(),
    BrownianEuler(),
    BrownianSplitting(),
)


def schemes_for(model: str) -> dict:
    """The registered schemes that integrate ``model``, by name, in registry order.

    Args:
        model: one of ``"vacuum"`` (`jaxrot.rollout` without ``fluid``), ``"fluid"`` (with a
            `jaxrot.Fluid` at ``kT = 0``), ``"thermal"`` (``kT > 0`` and a ``key``),
            ``"overdamped"`` (`jaxrot.overdamped_rollout` at ``kT = 0``) or ``"brownian"``
            (`jaxrot.overdamped_rollout` at ``kT > 0`` with a ``key``).

    Returns:
        ``dict[str, scheme]``: a new dict; each scheme's ``models`` holds ``model``.

    Raises:
        ValueError: an unknown model.

    Example:
        >>> import jaxrot
        >>> list(jaxrot.schemes_for("overdamped"))  # the Brownian schemes run it at kT = 0, without noise
        ['lie_euler', 'lie_midpoint', 'rkmk4', 'brownian_euler', 'brownian_splitting']
    """
    if model not in MODELS:
        raise ValueError(f"`model` must be one of {', '.join(map(repr, MODELS))}; got {model!r}.")
    return {name: scheme for name, scheme in REGISTRY.items() if model in scheme.models}


# The views, one per model (read-only, as they always were).
SCHEMES = MappingProxyType(schemes_for("vacuum"))
FLUID_SCHEMES = MappingProxyType(schemes_for("fluid"))
THERMAL_SCHEMES = MappingProxyType(schemes_for("thermal"))
OVERDAMPED_SCHEMES = MappingProxyType(schemes_for("overdamped"))
BROWNIAN_SCHEMES = MappingProxyType(schemes_for("brownian"))


def resolve_scheme(scheme):
    """A scheme object from a registered name or an instance (any model); ValueError otherwise.

    Whether it fits a call is the binder's to decide (`jaxrot._integrate._bind`)."""
    if isinstance(scheme, SCHEME_TYPES):
        return scheme
    if isinstance(scheme, str) and scheme in REGISTRY:
        return REGISTRY[scheme]
    raise ValueError(
        f"`scheme` must be one of {', '.join(map(repr, REGISTRY))} or a jaxrot.schemes.AbstractScheme "
        f"instance; got {scheme!r}."
    )
