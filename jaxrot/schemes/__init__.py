"""The integrators, one per file, registered by name in `SCHEMES`."""

from types import MappingProxyType

from ._base import AbstractScheme as AbstractScheme
from ._exponential import (
    AbstractExponentialLieRK as AbstractExponentialLieRK,
    ExponentialTableau as ExponentialTableau,
    FluidCarry as FluidCarry,
)
from ._lie_runge_kutta import (
    AbstractLieRungeKutta as AbstractLieRungeKutta,
    LieRungeKuttaCarry as LieRungeKuttaCarry,
)
from ._rkn_splitting import AbstractRKNSplitting as AbstractRKNSplitting
from .baoab import BAOAB as BAOAB
from .euler import Euler as Euler
from .exp_euler import ExpEuler as ExpEuler
from .exp_midpoint import ExpMidpoint as ExpMidpoint
from .exp_rk4 import ExpRK4 as ExpRK4
from .no_squish import NoSquish as NoSquish, NoSquishCarry as NoSquishCarry
from .rkmk4 import RKMK4 as RKMK4
from .rkmk_dopri5 import RKMKDopri5 as RKMKDopri5
from .rkmk_dopri8 import RKMKDopri8 as RKMKDopri8
from .rozmanov import Rozmanov as Rozmanov, RozmanovCarry as RozmanovCarry
from .splitting import Splitting as Splitting, SplittingCarry as SplittingCarry
from .srkn6b import SRKN6b as SRKN6b
from .srkn14a import SRKN14a as SRKN14a
from .zhao import Zhao as Zhao


SCHEMES = MappingProxyType(
    {
        scheme.name: scheme
        for scheme in (
            Zhao(),
            Rozmanov(),
            Euler(),
            NoSquish(),
            Splitting(),
            RKMK4(),
            RKMKDopri5(),
            RKMKDopri8(),
            SRKN6b(),
            SRKN14a(),
        )
    }
)

# The exponential schemes, which integrate a fluid's friction with no step limit (`jaxrot.Fluid`):
# named by `jaxrot.rollout` like the others, kept out of `SCHEMES`, whose every member the
# results files under docs/ cover.
FLUID_SCHEMES = MappingProxyType({scheme.name: scheme for scheme in (ExpMidpoint(), ExpRK4())})

# The schemes of `jaxrot.rollout` that integrate the thermal torque (underdamped Langevin).
THERMAL_SCHEMES = MappingProxyType({s.name: s for s in (BAOAB(), ExpEuler())})


def resolve_scheme(scheme) -> AbstractScheme:
    """A scheme object from a name in `SCHEMES`, `FLUID_SCHEMES` or `THERMAL_SCHEMES`, or an instance."""
    if isinstance(scheme, AbstractScheme):
        return scheme
    if isinstance(scheme, str) and scheme in SCHEMES:
        return SCHEMES[scheme]
    if isinstance(scheme, str) and scheme in FLUID_SCHEMES:
        return FLUID_SCHEMES[scheme]
    if isinstance(scheme, str) and scheme in THERMAL_SCHEMES:
        return THERMAL_SCHEMES[scheme]
    raise ValueError(
        f"`scheme` must be one of {sorted(SCHEMES) + sorted(FLUID_SCHEMES) + sorted(THERMAL_SCHEMES)} or a "
        f"jaxrot.schemes.AbstractScheme instance; got {scheme!r}."
    )
