"""Pair sampling obeys the 2 m rule: positives closer than 2 m (same view, other condition), negatives farther."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.errors import InputError
from topoloc.place.pair_data import PairBatches
from topoloc.place.pairs import IGNORE, PairSampler, heading_difference, pair_distances


def two_streets() -> tuple[np.ndarray, np.ndarray]:
    """Places every 0.7 m along an east-bound street, and the same street driven west-bound 1 m beside it."""
    x = np.arange(0.0, 200.0, 0.7)
    east = np.column_stack([x, np.zeros_like(x)])
    west = np.column_stack([x[::-1], np.full_like(x, 1.0)])
    xy = np.concatenate([east, west])
    yaw = np.concatenate([np.zeros(len(x)), np.full(len(x), np.pi)])
    return xy, yaw


def test_pairs_obey_the_two_metre_rule():
    xy, yaw = two_streets()
    sampler = PairSampler(xy, yaw, [0, 2, 5], positive_m=2.0, hard_negative_m=(3.0, 30.0), hard_share=0.5)
    pairs = sampler.sample(4000, np.random.default_rng(0))
    d = pair_distances(xy, pairs)
    dh = heading_difference(yaw[pairs.place_a], yaw[pairs.place_b])
    pos, neg = pairs.label == 1, pairs.label == 0
    assert 0.45 < pos.mean() < 0.55
    assert np.all(d[pos] < 2.0) and np.all(dh[pos] <= 30.0)
    assert np.all(d[neg] > 2.0)
    assert np.all(pairs.cond_a != pairs.cond_b)  # across conditions, both labels
    assert set(np.unique(pairs.cond_a)) == {0, 2, 5}
    # hard negatives: same heading, 3-30 m apart; about half the negatives
    hard = neg & (d >= 3.0) & (d <= 30.0) & (dh <= 30.0)
    assert 0.4 < hard[neg].mean() < 0.7
    # a place and the opposite carriageway 1 m away are never paired
    assert not np.any((d < 2.0) & (dh > 30.0))


def test_label_matrix_and_clustered_batches():
    xy, yaw = two_streets()
    sampler = PairSampler(xy, yaw, [0, 1])
    pairs = sampler.sample_clustered(32, 4, np.random.default_rng(1))
    assert np.all(pair_distances(xy, pairs) < 2.0) and np.all(pairs.label == 1)
    labels = sampler.label_matrix(pairs.place_a, pairs.place_b)
    assert labels.shape == (32, 32) and np.all(np.diag(labels) == 1)
    d = np.hypot(*(xy[pairs.place_a][:, None] - xy[pairs.place_b][None]).transpose(2, 0, 1))
    dh = heading_difference(yaw[pairs.place_a][:, None], yaw[pairs.place_b][None])
    assert np.all(labels[d > 2.0] == 0)
    assert np.all(labels[(d < 2.0) & (dh <= 30.0)] == 1)
    assert np.all(labels[(d <= 2.0) & (dh > 30.0)] == IGNORE)
    # groups of four anchors on one street: hard negatives among each other
    group = np.hypot(*(xy[pairs.place_a[:4]] - xy[pairs.place_a[0]]).T)
    assert np.all(group <= 30.0)


def test_in_batch_pairs_are_all_across_conditions():
    xy, yaw = two_streets()
    images = np.zeros((3, len(xy), 4, 4, 1), np.uint8)
    batches = PairBatches(images, np.arange(len(xy)), PairSampler(xy, yaw, [0, 1, 2]), batches=4, batch_size=32,
                          seed=0, in_batch=True, cluster=4)
    for k in range(len(batches)):
        labels = batches[k][2].numpy()
        rng = np.random.default_rng([0, 0, k])  # the batch's own draw
        pairs = batches.sampler.sample_clustered(32, 4, rng)
        same = pairs.cond_a[:, None] == pairs.cond_b[None]
        assert same.sum() > 32 and np.all(labels[same] == IGNORE)  # with three conditions, about a third
        rule = batches.sampler.label_matrix(pairs.place_a, pairs.place_b)
        assert np.all(np.diag(labels) == 1) and np.array_equal(labels[~same], rule[~same])


def test_bad_pair_settings_name_the_key():
    xy, yaw = two_streets()
    with pytest.raises(InputError, match=r"^place.train.conditions: "):
        PairSampler(xy, yaw, [0])
    with pytest.raises(InputError, match=r"^place.pairs.hard_negative_m: "):
        PairSampler(xy, yaw, [0, 1], positive_m=2.0, hard_negative_m=(1.0, 30.0))
