"""The top places of a bank's beliefs (``topoloc.localization.places.belief_places``), for all filters or some."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.localization.places import belief_places


def bank(seed: int, roads: int = 4) -> dict:
    """Three filters' entries over two cells per road, cells of one road repeating."""
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, 3, 60)
    cell = rng.integers(0, 2 * roads, 60)
    weight = rng.random(60)
    for f in range(3):
        weight[owner == f] /= weight[owner == f].sum()
    edge = np.repeat(np.arange(roads), 2)
    xy = np.column_stack([np.arange(2.0 * roads), np.zeros(2 * roads)])
    return dict(owner=owner, cell=cell, weight=weight, cell_edge=edge, cell_xy=xy, filters=3, roads=roads, k=2)


@pytest.mark.parametrize("roads", [4, 12])  # every road a candidate; the 8 likeliest of 12 (argpartition)
def test_places_of_some_filters_are_theirs_among_all(roads):
    for seed in range(5):
        args = bank(seed, roads)
        every = belief_places(**args)
        assert len(every) == 3
        for which in ([2, 0], [1], [0, 1, 2], []):
            assert belief_places(**args, which=np.array(which, np.int64)) == [every[f] for f in which]


def test_a_place_is_a_roads_mass_at_its_cell_of_most_mass():
    args = bank(3)
    owner, cell, weight, edge = args["owner"], args["cell"], args["weight"], args["cell_edge"]
    for f, places in enumerate(belief_places(**args)):
        mass = np.bincount(edge[cell[owner == f]], weights=weight[owner == f], minlength=4)
        assert [p.state for p in places] == list(np.argsort(-mass, kind="stable")[:2])
        for p in places:
            assert np.isclose(p.probability, mass[p.state])
            per_cell = np.bincount(cell[owner == f], weights=weight[owner == f], minlength=8)
            road_cells = np.flatnonzero(edge == p.state)
            assert p.xy[0] == road_cells[np.argmax(per_cell[road_cells])]  # cell k lies at x = k


def test_the_entries_of_one_cell_add_up_for_its_position():
    # cell 0 held twice (two scale classes, 0.3 each) outweighs cell 1's single largest entry (0.4)
    args = dict(owner=np.zeros(3, np.int64), cell=np.array([0, 1, 0]), weight=np.array([0.3, 0.4, 0.3]),
                cell_edge=np.array([0, 0]), cell_xy=np.array([[0.0, 0.0], [1.0, 0.0]]), filters=1, roads=1, k=1)
    [[place]] = belief_places(**args)
    assert place.state == 0 and np.isclose(place.probability, 1.0) and place.xy[0] == 0.0


def test_the_cell_of_most_mass_breaks_a_tie_to_the_lowest_cell_in_any_order():
    from topoloc.localization.places import cells_of_most_mass

    owner, cell, mass = np.zeros(4, np.int64), np.array([5, 2, 7, 3]), np.array([0.3, 0.1, 0.3, 0.3])
    edge = np.zeros(8, np.int64)  # one road
    for order in ([0, 1, 2, 3], [3, 2, 1, 0], [2, 0, 3, 1]):
        best, best_cell = cells_of_most_mass(owner[order], cell[order], mass[order], edge, 1, 1)
        assert best[0] == 0.3 and best_cell[0] == 3
