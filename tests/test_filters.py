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


def _ranked_filters():
    """A started filter of every class with ``top_places``, after a short drive on a small grid (its belief still spread
    over many roads): (filter, its answer's (road, confidence))."""
    import sys
    from pathlib import Path

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent / "localization"))
    from localization_helpers import irregular_grid

    from topoloc.config import load
    from topoloc.localization.hmm import CellHMM, HmmParams
    from topoloc.localization.metric.city_filter import CityFilter
    from topoloc.localization.metric.dense_filter import MetricFilter
    from topoloc.localization.metric.map_model import MetricModel, MetricSettings
    from topoloc.localization.metric.restart import RestartingFilter
    from topoloc.localization.roadmap import RoadMap

    graph, _ = irregular_grid()
    road = RoadMap(graph)
    conf = load(None)["localization"]
    model = MetricModel(graph, road.states, MetricSettings.from_conf(conf["metric"]))
    yaws = np.radians(np.r_[np.zeros(60), np.full(40, 90.0)])  # 120 m east, then 80 m north, in 2 m steps
    built = {}
    for cls in (MetricFilter, CityFilter, RestartingFilter):
        filt = cls(model) if cls is MetricFilter else cls(model, None)
        filt.start()
        for yaw in yaws:
            filt.update(1, float(yaw))
        est = filt.answer(0)
        built[cls] = (filt, (est.edge, est.confidence))
    hmm = CellHMM(graph, road.states, 20, HmmParams.from_conf(conf["hmm"]))
    hmm.start()
    for token in (10, 10, 10, 10, 10, 5, 10, 10, 10):
        hmm.update(token)
    built[CellHMM] = (hmm, hmm.answer())
    return built


def test_filters_with_top_places_rank_them():
    """Where a filter has ``top_places`` (:class:`topoloc.localizer.RankedFilter`): at most ``k`` places, most probable
    first, their probabilities summing to at most 1, the first the filter's own answer when nothing is merged, and
    merging only adds up."""
    import numpy as np

    from topoloc.localizer import RankedFilter

    ranked = [cls for cls in filter_classes() if callable(getattr(cls, "top_places", None))]
    built = _ranked_filters()
    assert {c.__name__ for c in ranked} >= {"MetricFilter", "CityFilter", "CellHMM"}
    for cls in ranked:
        assert issubclass(cls, RankedFilter)
        assert cls in built, f"{cls.__name__} has top_places: add it to _ranked_filters"
        filt, (edge, confidence) = built[cls]
        places = filt.top_places(3, 0.0)
        probs = np.array([p.probability for p in places])
        assert len({p.state for p in places}) == 3 and (np.diff(probs) <= 1e-9).all() and probs.sum() <= 1.0 + 1e-5, (cls, places)
        assert places[0].state == edge and abs(places[0].probability - confidence) < 1e-5, (cls, places, edge, confidence)
        assert all(p.xy is not None and np.isfinite(p.xy).all() for p in places)
        # merging within the spread of the unmerged top places: the top place absorbs the other two (no mass lost),
        # at most k places are left, no mass is made up, and what else is kept lies farther off than the radius
        xy = np.array([p.xy for p in places])
        radius = float(np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)).max()) + 1.0
        merged = filt.top_places(3, radius)
        merged_probs = np.array([p.probability for p in merged])
        assert 1 <= len(merged) <= 3 and merged_probs.sum() <= 1.0 + 1e-5, (cls, merged)
        assert merged[0].state == places[0].state and merged[0].probability >= probs.sum() - 1e-6, (cls, merged, places)
        assert all(np.hypot(*(np.subtract(p.xy, merged[0].xy))) > radius for p in merged[1:]), (cls, merged, radius)
