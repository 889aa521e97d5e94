"""The integrators, one per file, registered by name in `SCHEMES`."""

from types import MappingProxyType

from ._base import AbstractScheme as AbstractScheme
from .euler import Euler as Euler
from .no_squish import NoSquish as NoSquish, NoSquishCarry as NoSquishCarry
from .rozmanov import Rozmanov as Rozmanov, RozmanovCarry as RozmanovCarry
from .splitting import Splitting as Splitting, SplittingCarry as SplittingCarry
from .zhao import Zhao as Zhao


SCHEMES = MappingProxyType(
    {scheme.name: scheme for scheme in (Zhao(), Rozmanov(), Euler(), NoSquish(), Splitting())}
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
