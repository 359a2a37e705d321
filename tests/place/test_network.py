"""The siamese network: shapes and signature, the metric start of its head, local weights, and overfitting."""

from __future__ import annotations

import lightning as L
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from tests.place.conftest import place_conf
from topoloc.place.network import SiameseNet, augment, box_mean, local_normalize
from topoloc.place.train_retrieval import build_model


def textures(n: int, seed: int, h: int = 48, w: int = 64) -> np.ndarray:
    """``n`` random blocky colour images (uint8, (n, h, w, 3))."""
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 255, (n, h // 8, w // 8, 3)).astype(np.uint8)
    return np.repeat(np.repeat(small, 8, axis=1), 8, axis=2)


def test_forward_embed_and_score_agree():
    torch.manual_seed(0)
    model = SiameseNet(channels=[8, 16], embedding_dim=16, hidden=32).eval()
    images = textures(6, 0)
    pairs = torch.from_numpy(np.stack([images[:3], images[3:]], axis=1)).permute(0, 1, 4, 2, 3).float()
    probs = model(pairs).detach().numpy()
    assert probs.shape == (3, 2) and np.allclose(probs.sum(1), 1.0, atol=1e-6)
    emb = model.embed(images)
    assert emb.shape == (6, 16) and np.allclose(np.linalg.norm(emb, axis=1), 4.0, atol=1e-4)
    scores = [model.same_place(emb[k], emb[3 + k:4 + k])[0] for k in range(3)]
    assert np.allclose(scores, probs[:, 1], atol=1e-5)
    # the score matrix of all queries against all references is same_place row by row
    matrix = model.score_matrix(emb[:4], emb, chunk=3)
    assert matrix.shape == (4, 6)
    assert np.allclose(matrix, [model.same_place(q, emb) for q in emb[:4]], atol=1e-5)
    # the head starts as an L1 distance: an image against itself scores sigmoid(4)
    assert model.same_place(emb[0], emb[:1])[0] == pytest.approx(1 / (1 + np.exp(-4.0)), abs=1e-5)
    # brightness and contrast changes are (nearly) normalised away before the backbone
    x = torch.from_numpy(textures(1, 3, 48, 64) // 4 + 100).permute(0, 3, 1, 2).float()
    y = 0.5 * x + 20.0
    corr = np.corrcoef(local_normalize(x).flatten().numpy(), local_normalize(y).flatten().numpy())[0, 1]
    assert corr > 0.98
    aug = augment(x.repeat(4, 1, 1, 1), torch.Generator().manual_seed(0))
    assert aug.shape == (4, 3, 48, 64) and aug.min() >= 0 and aug.max() <= 255


def test_a_model_left_in_training_mode_embeds_as_in_eval_mode():
    torch.manual_seed(0)
    model = SiameseNet(channels=[8, 16], embedding_dim=16, hidden=32).eval()
    images = textures(4, 1)
    expected = model.embed(images)
    model.train()  # what a fit leaves behind: batch norm on batch statistics until eval mode is restored
    assert np.allclose(model.embed(images), expected, atol=1e-6)
    assert not model.training and not any(m.training for m in model.modules())


def test_box_mean_is_the_replicate_padded_average_pool():
    x = torch.rand(2, 3, 20, 30) * 255
    for size in (3, 9):
        pad = size // 2
        reference = torch.nn.functional.avg_pool2d(torch.nn.functional.pad(x, (pad,) * 4, mode="replicate"), size, 1)
        assert torch.allclose(box_mean(x, size), reference, atol=1e-3)
    with pytest.raises(ValueError, match="odd"):
        box_mean(x, 4)


def test_local_weights_are_loaded(tmp_path):
    conf = place_conf()
    first = build_model(conf, 3, ["a", "b"])
    torch.save(first.state_dict(), tmp_path / "w.pt")
    second = build_model(place_conf(network={"weights": str(tmp_path / "w.pt")}), 3, ["a", "b"])
    images = textures(3, 1)
    assert np.allclose(first.embed(images), second.embed(images))


@pytest.mark.parametrize(("head_init", "steps", "margin"), [("metric", 100, 0.9), ("random", 300, 0.5)])
def test_tiny_model_overfits_a_handful_of_pairs(head_init, steps, margin):
    """Four places under two 'conditions' (other exposure and tint), trained as one in-batch batch:
    4 positives and 12 negatives; the default metric head in 100 steps, a randomly started one in 300."""
    torch.manual_seed(0)
    base = textures(4, 2).astype(np.float32)
    other = np.clip(base * np.array([0.6, 0.8, 1.1]) + 25.0, 0, 255).astype(np.float32)
    labels = torch.eye(4, dtype=torch.long)  # anchor i against partner j: same place when i == j
    batch = TensorDataset(torch.tensor(base)[None], torch.tensor(other)[None], labels[None])
    model = SiameseNet(channels=[8, 16], embedding_dim=16, hidden=32, lr=1e-3, lr_decay=1.0, augment=False,
                       head_init=head_init)
    trainer = L.Trainer(max_epochs=steps, accelerator="cpu", logger=False, enable_checkpointing=False,
                        enable_progress_bar=False, enable_model_summary=False)
    trainer.fit(model, DataLoader(batch, batch_size=None))
    model.eval()
    a = torch.tensor(base).permute(0, 3, 1, 2).repeat_interleave(4, 0)
    b = torch.tensor(other).permute(0, 3, 1, 2).repeat(4, 1, 1, 1)
    with torch.no_grad():
        probs = torch.softmax(model.logits(a, b), 1)[:, 1].numpy()
    same = labels.flatten().numpy().astype(bool)
    assert probs[same].min() > margin and probs[~same].max() < 1.0 - margin, probs.round(2)
