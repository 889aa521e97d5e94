"""The integrators, one per file, registered by name in `SCHEMES`."""

from types import MappingProxyType

from ._base import AbstractScheme as AbstractScheme
from ._lie_runge_kutta import (
    AbstractLieRungeKutta as AbstractLieRungeKutta,
    LieRungeKuttaCarry as LieRungeKuttaCarry,
)
from ._rkn_splitting import AbstractRKNSplitting as AbstractRKNSplitting
from .euler import Euler as Euler
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


def resolve_scheme(scheme) -> AbstractScheme:
    """A scheme object from a name in `SCHEMES` or an `AbstractScheme` instance."""
    if isinstance(scheme, AbstractScheme):
        return scheme
    if isinstance(scheme, str) and scheme in SCHEMES:
        return SCHEMES[scheme]
    raise ValueError(
        f"`scheme` must be one of {sorted(SCHEMES)} or a jaxrot.schemes.AbstractScheme instance; "
        f"got {scheme!r}."
    )
