"""Every filter follows :class:`topoloc.localizer.Filter`: the classes of the localization, localizer and place
packages that take observations one at a time are found by their methods, and each must have ``start``,
``update`` and ``answer`` and none of the old names (``step``, ``trace``, ``decode``; ``reset`` only as
:meth:`topoloc.localizer.Localizer.reset` ``(map, conf)``)."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

from topoloc.localizer import Filter, Localizer

PACKAGES = ("localization", "localizers", "place")
#: Method names of a filter before there was one vocabulary.
OLD_NAMES = ("step", "trace", "decode", "reset")
#: A class with one of these methods takes observations one at a time.
ONLINE = ("start", "update", "step")


def filter_classes(packages: tuple[str, ...] = PACKAGES) -> list[type]:
    """Every class defined in ``topoloc.<package>`` (any depth) with a method of :data:`ONLINE`."""
    found = []
    for package in packages:
        root = importlib.import_module(f"topoloc.{package}")
        names = [root.__name__] + [m.name for m in pkgutil.walk_packages(root.__path__, root.__name__ + ".")]
        for name in names:
            module = importlib.import_module(name)
            for value in vars(module).values():
                if (isinstance(value, type) and value.__module__ == name
                        and any(callable(vars(value).get(m)) for m in ONLINE)):
                    found.append(value)
    return sorted(set(found), key=lambda c: f"{c.__module__}.{c.__qualname__}")


def violations(cls: type) -> list[str]:
    """How ``cls`` departs from :class:`Filter`: missing methods, old names."""
    out = [f"no {m}()" for m in ("start", "update", "answer") if not callable(getattr(cls, m, None))]
    for old in OLD_NAMES:
        if old == "reset" and issubclass(cls, Localizer) and cls.reset is Localizer.reset:
            continue  # the localizer's reset(map, conf): setup, then start
        if callable(getattr(cls, old, None)):
            out.append(f"{old}() is an old name")
    return out


def test_the_filters_are_found():
    names = {cls.__name__ for cls in filter_classes()}
    assert {"MetricFilter", "CityFilter", "CellHMM", "Beam", "OnlineRNN", "BayesFilter", "WindowSearch",
            "PathIntegration", "MetricLocalizer", "HmmBaseline", "RnnFilter", "PlaceFilter"} <= names


@pytest.mark.parametrize("cls", filter_classes(), ids=lambda c: f"{c.__module__.removeprefix('topoloc.')}.{c.__name__}")
def test_every_filter_follows_the_protocol(cls):
    assert not violations(cls), violations(cls)
    assert issubclass(cls, Filter)


def test_the_check_catches_an_old_filter():
    class Old:
        def reset(self) -> None: ...
        def step(self, x: int) -> int: return x
        def trace(self) -> list[int]: return []

    class Renamed(Old):
        def start(self) -> None: ...
        def update(self, x: int) -> int: return x
        def answer(self) -> int: return 0

    assert violations(Old) == ["no start()", "no update()", "no answer()", "step() is an old name",
                               "trace() is an old name", "reset() is an old name"]
    assert violations(Renamed) == ["step() is an old name", "trace() is an old name", "reset() is an old name"]
    assert not issubclass(Old, Filter)
