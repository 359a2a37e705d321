"""The localizers by name: the registry that the stages, the CLI and the workflow ask.

:func:`registry` imports every module of the package :mod:`topoloc.localizers`, where each localizer
registers itself (:func:`topoloc.localizer.register`), so a new localizer is one module there. The
interface itself (:mod:`topoloc.localizer`) discovers nothing: a module that only implements or drives a
localizer does not depend on every other one (nor does its code digest, :mod:`topoloc.code_digest`).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Collection, Sequence

from topoloc.errors import InputError
from topoloc.localizer import _REGISTRY, OBSERVATIONS, Localizer


def registry(observes: Collection[str] = OBSERVATIONS) -> dict[str, type[Localizer]]:
    """Every registered localizer that observes one of ``observes`` (default: all) by name, in registration
    order (imports :mod:`topoloc.localizers`). Road stages pass :data:`ROAD_OBSERVATIONS`."""
    package = importlib.import_module("topoloc.localizers")
    for module in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        importlib.import_module(f"{package.__name__}.{module.name}")
    return {name: cls for name, cls in _REGISTRY.items() if cls.observes in observes}


def make(name: str, observes: Collection[str] = OBSERVATIONS) -> Localizer:
    """A new localizer of the registered ``name`` (among those observing ``observes``); KeyError naming the choices otherwise."""
    known = registry(observes)
    if name not in known:
        raise KeyError(f"unknown localizer {name!r}; choose from {sorted(known)}")
    return known[name]()


def check_names(names: Sequence[str], where: str = "localization.localizers",
                observes: Collection[str] = OBSERVATIONS) -> list[str]:
    """``names`` if every one is registered (among those observing ``observes``); else InputError naming the first unknown one."""
    known = registry(observes)
    for index, name in enumerate(names):
        if name not in known:
            raise InputError(f"{where}.{index}", f"unknown localizer {name!r}; choose from {sorted(known)}")
    return list(names)
