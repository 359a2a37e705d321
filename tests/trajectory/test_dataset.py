"""Token/label encoding of paths, the dataset files, reproducibility and bad input."""

from __future__ import annotations

import hashlib

import numpy as np
import pyarrow.parquet as pq
import pytest
from trajectory_helpers import make_graph, random_graph

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.geometry import quantize_angle
from topoloc.trajectory.dataset import (
    MAX_OFFSET,
    Noise,
    PathEncoder,
    load_sequences,
    load_state_targets,
    state_targets,
)
from topoloc.trajectory.generate_dataset import generate, table_i
from topoloc.trajectory.paths import Path, sample_paths

STRAIGHT = 10  # straight token with 20 bins
LEFT = quantize_angle(90.0, 20)
RIGHT = quantize_angle(270.0, 20)


def conf(**dataset):
    """The generate_dataset slice of the defaults: 3-node paths, a quarter for validation, small shards; ``dataset`` keys."""
    config = make_config(dataset={"source": "dfs", "path_nodes": 3, "val_fraction": 0.25, "shard_rows": 4, **dataset})
    return {"encoding": config["encoding"], "dataset": config["dataset"]}


@pytest.fixture
def tee():
    """A(0,0) -100 m- B(100,0); B -50 m- C(100,50) to the north; B -70 m- D(100,-70) to the south."""
    return make_graph({1: (0, 0), 2: (100, 0), 3: (100, 50), 4: (100, -70)}, [(1, 2), (2, 3), (4, 2)], spacing=20.0)


def test_left_and_right_turns_with_virtual_nodes(tee):
    assert (LEFT, RIGHT) == (5, 15)
    encoder = PathEncoder(tee, 20, 10.0)
    tokens, labels = encoder.encode(Path((1, 2, 3), (0, 1)))  # 100 m east (4 virtual nodes), left, 50 m north (2)
    assert tokens.tolist() == [STRAIGHT] * 4 + [LEFT] + [STRAIGHT] * 2
    assert labels.tolist() == [0] * 4 + [1] * 3
    tokens, labels = encoder.encode(Path((1, 2, 4), (0, 2)))  # right onto edge 2, travelled v->u (70 m: 3 virtual)
    assert tokens.tolist() == [STRAIGHT] * 4 + [RIGHT] + [STRAIGHT] * 3
    assert labels.tolist() == [0] * 4 + [2] * 4
    tokens, labels = encoder.encode(Path((3, 2, 4), (1, 2)))  # straight on through B, north to south
    assert tokens.tolist() == [STRAIGHT] * 2 + [STRAIGHT] + [STRAIGHT] * 3
    assert labels.tolist() == [1] * 2 + [2] * 4  # the token at B already lies on the new edge



def test_segmented_encoding_is_that_of_a_drive(tee):
    seg = {"tolerance_m": 5.0, "corner_skip_m": 10.0, "turn_label_offset_m": 5.0}
    encoder = PathEncoder(tee, 20, 10.0, seg)
    # straight on through B (50 m + 70 m): one straight segment of 120 m, no token for B, 5 virtual nodes
    tokens, labels = encoder.encode(Path((3, 2, 4), (1, 2)))
    assert tokens.tolist() == [STRAIGHT] * 5
    assert labels.tolist() == [1, 1, 2, 2, 2]  # virtual nodes at 20, 40 (edge 1), 60, 80, 100 m (edge 2)
    tokens, labels = encoder.encode(Path((1, 2, 3), (0, 1)))  # a corner at B: the same as the node encoding
    assert tokens.tolist() == [STRAIGHT] * 4 + [LEFT] + [STRAIGHT] * 2
    assert labels.tolist() == [0] * 4 + [1] * 3
    noisy = encoder.encode(Path((1, 2, 3), (0, 1)), np.random.default_rng(0), Noise(1, 5.0, 0.1))
    assert len(noisy[0]) == len(noisy[1]) and set(noisy[1].tolist()) <= {0, 1}

def test_encoder_matches_shared_encoding_module():
    from topoloc.encoding import encode_segments, polyline_end_headings

    graph = random_graph(5, n=10, extra=4)
    encoder = PathEncoder(graph, 20, 10.0)
    for path in sample_paths(graph, 4, respect_oneway=False, max_total=50):
        heads = [polyline_end_headings(graph.edge_coords(e, n), 10.0) for e, n in zip(path.edges, path.nodes)]
        expected = encode_segments(graph.edges.length_m.to_numpy()[list(path.edges)], [h[0] for h in heads],
                                   [h[1] for h in heads], graph.virtual_node_spacing_m, 20)
        tokens, labels = encoder.encode(path)
        assert tokens.tolist() == expected.tokens.tolist()
        assert labels.tolist() == np.asarray(path.edges)[expected.segment].tolist()


def test_dataset_files_split_and_stats(tee, tmp_path):
    stats = generate(tee, conf(val_fraction=0.3), str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"))
    # 3-node paths on the tee: every ordered pair of its 3 roads = 6 paths
    assert stats["trajectories"] == 6 == stats["train_trajectories"] + stats["val_trajectories"]
    assert stats["val_trajectories"] >= 1 and stats["classes"] == 3 and stats["input_feature_space"] == 20
    train = pq.read_table(tmp_path / "t.parquet").to_pylist()
    val = pq.read_table(tmp_path / "v.parquet").to_pylist()
    ids = [r["path_id"] for r in train + val]
    assert sorted(ids) == list(range(6))  # split by whole paths
    for row in train + val:
        assert len(row["tokens"]) == len(row["labels"]) and row["labels"][-1] == row["edges"][-1]
    tokens, labels = load_sequences(tmp_path / "t.parquet")
    assert [t.tolist() for t in tokens] == [r["tokens"] for r in train]
    assert "| Topological Map | 4 nodes, 3 edges |" in table_i(stats, "tee")


def test_same_seed_same_bytes_other_seed_other_split(tmp_path):
    graph = random_graph(1, n=14, extra=8)

    def digest(seed, name):
        c = conf(path_nodes=5, seed=seed, respect_oneway=False, augment={"copies": 2, "angle_std_deg": 5.0, "spacing_rel_std": 0.1})
        generate(graph, c, str(tmp_path / f"{name}t.parquet"), str(tmp_path / f"{name}v.parquet"))
        return [hashlib.sha256((tmp_path / f"{name}{s}.parquet").read_bytes()).hexdigest() for s in "tv"]

    assert digest(3, "a") == digest(3, "b")
    assert digest(3, "a") != digest(4, "c")


def test_augmentation_adds_noisy_copies_of_train_paths_only(tmp_path):
    graph = random_graph(2, n=10, extra=5)
    c = conf(path_nodes=4, respect_oneway=False, augment={"copies": 2, "angle_std_deg": 20.0, "spacing_rel_std": 0.3})
    stats = generate(graph, c, str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"))
    train = pq.read_table(tmp_path / "t.parquet").to_pandas()
    val = pq.read_table(tmp_path / "v.parquet").to_pandas()
    assert len(train) == 3 * stats["train_trajectories"] and (val["copy"] == 0).all()
    clean = train[train["copy"] == 0].set_index("path_id").tokens
    noisy = train[train["copy"] > 0]
    assert any(list(r.tokens) != list(clean[r.path_id]) for r in noisy.itertuples())
    assert all(r.labels[-1] == r.edges[-1] for r in noisy.itertuples())


def test_bad_input_names_the_key(tee, tmp_path):
    out = (str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"))
    with pytest.raises(InputError, match=r"^dataset.path_nodes: .*only 4 nodes"):
        generate(tee, conf(path_nodes=5), *out)
    with pytest.raises(InputError, match=r"^dataset.path_nodes: no simple path with 4 nodes"):
        generate(tee, conf(path_nodes=4), *out)  # a star has no 4-node simple path: empty dataset
    assert not (tmp_path / "t.parquet").exists()  # nothing half-written
    with pytest.raises(InputError, match=r"^config key 'encoding.angle_bins': 3 is less than the minimum of 4"):
        make_config(encoding={"angle_bins": 3})  # what the schema checks, the stage does not check again


def test_state_targets_direction_and_offset_along_each_edge():
    # nodes 5 -e7- 3 -e1- 9 -e4- 2: e7 travelled towards the lower id, e1 towards the higher, e4 the lower
    directions, offsets = state_targets([5, 3, 9, 2], [7, 1, 4], np.array([7, 7, 1, 1, 1, 4]))
    assert directions.tolist() == [0, 0, 1, 1, 1, 0]
    assert offsets.tolist() == [0, 1, 0, 1, 2, 0]
    # a first edge without virtual nodes has no token: the labels start on the second edge
    directions, offsets = state_targets([5, 3, 9, 2], [7, 1, 4], np.array([1] * 40 + [4]))
    assert directions.tolist() == [1] * 40 + [0]
    assert offsets.max() == MAX_OFFSET and offsets[-1] == 0


def test_state_targets_of_a_dataset_file(tmp_path, tee):
    stats = generate(tee, conf(path_nodes=3, val_fraction=0.0), str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"))
    tokens, labels = load_sequences(tmp_path / "t.parquet")
    directions, offsets = load_state_targets(tmp_path / "t.parquet")
    assert len(directions) == stats["train_trajectories"]
    assert all(len(d) == len(o) == len(t) for d, o, t in zip(directions, offsets, tokens))
