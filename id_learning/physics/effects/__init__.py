"""The registry of physical effects: one object per effect, asked instead of its name.

``effect(name)`` gives the object that knows an effect's parameters, label, columns and form;
``EFFECT_NAMES`` lists them in the library's stable order. Adding an effect or a form is a class
in ``library`` and its tests.
"""

from __future__ import annotations

from id_learning.errors import ConfigError
from id_learning.physics.effects.base import Effect, FittedTerm, JointEffect, Parameter
from id_learning.physics.effects.library import LIBRARY

__all__ = [
    'EFFECT_NAMES',
    'FRICTION_LAWS',
    'REGISTRY',
    'Effect',
    'FittedTerm',
    'JointEffect',
    'Parameter',
    'effect',
    'friction_law',
]

#: name -> effect, in the library's order.
REGISTRY: dict[str, Effect] = {item.name: item for item in LIBRARY}
#: The effects' stable names, in the library's order.
EFFECT_NAMES: tuple[str, ...] = tuple(REGISTRY)
#: The friction laws an identified model fits per joint (``Effect.law``), in library order.
FRICTION_LAWS: tuple[str, ...] = tuple(item.law for item in LIBRARY if item.law)
_LAWS = {item.law: item for item in LIBRARY if item.law}


def effect(name: str) -> Effect:
    """The effect of that name.

    Raises:
        ConfigError: no effect has that name (the known ones listed).
    """
    try:
        return REGISTRY[name]
    except KeyError:
        raise ConfigError(
            f'unknown effect {name!r}; known effects: {list(EFFECT_NAMES)}'
        ) from None


def friction_law(law: str) -> Effect:
    """The effect whose friction law an identified model calls ``law``.

    Raises:
        ConfigError: no effect has that law (the known ones listed).
    """
    try:
        return _LAWS[law]
    except KeyError:
        raise ConfigError(f'unknown friction law {law!r}; known: {list(FRICTION_LAWS)}') from None
