"""Inference copies: batch norms folded into their convolutions, the same outputs, rebuilt when the weights change."""

from __future__ import annotations

import pickle

import numpy as np
import torch
from torch import nn

from topoloc.drive.controller import TopoDLM
from topoloc.fast_inference import InferenceCopy, fold_batch_norms
from topoloc.place.network import BasicBlock, SiameseNet


def _with_batch_statistics(module: nn.Module, seed: int) -> nn.Module:
    """``module`` in eval mode with random running statistics and affine weights (a fresh batch norm is the identity)."""
    g = torch.Generator().manual_seed(seed)
    for m in module.modules():
        if isinstance(m, nn.BatchNorm2d):
            n = m.num_features
            m.running_mean.copy_(torch.randn(n, generator=g))
            m.running_var.copy_(0.5 + torch.rand(n, generator=g))
            with torch.no_grad():
                m.weight.copy_(0.5 + torch.rand(n, generator=g))
                m.bias.copy_(torch.randn(n, generator=g))
    return module.eval()


def _batch_norms(module: nn.Module) -> int:
    return sum(isinstance(m, nn.BatchNorm2d) for m in module.modules())


def test_folding_removes_each_batch_norm_after_a_convolution_and_keeps_the_outputs():
    torch.manual_seed(0)
    net = _with_batch_statistics(nn.Sequential(
        nn.Conv2d(3, 8, 3, 2, 1, bias=False), nn.BatchNorm2d(8), nn.ReLU(), BasicBlock(8, 16, 2), BasicBlock(16, 16, 1),
        nn.BatchNorm2d(16)), seed=1)  # the last batch norm follows a ReLU: it stays
    x = torch.rand(2, 3, 24, 32) * 255
    folded = fold_batch_norms(net)
    assert _batch_norms(net) == 7 and _batch_norms(folded) == 1
    with torch.no_grad():
        assert torch.allclose(folded(x), net(x), rtol=1e-4, atol=1e-4)
    assert _batch_norms(net) == 7  # the module itself is untouched


def test_a_convolution_used_twice_keeps_its_batch_norm():
    class Both(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.conv, self.bn = nn.Conv2d(3, 4, 3, padding=1), nn.BatchNorm2d(4)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            y = self.conv(x)
            return self.bn(y) + y

    net = _with_batch_statistics(Both(), seed=2)
    folded = fold_batch_norms(net)
    assert _batch_norms(folded) == 1
    x = torch.rand(1, 3, 8, 8)
    with torch.no_grad():
        assert torch.allclose(folded(x), net(x), atol=1e-5)


def test_the_copy_follows_the_weights_after_a_training_step_and_pickles_without_the_copy():
    torch.manual_seed(0)
    net = nn.Sequential(nn.Conv2d(3, 4, 3, padding=1, bias=False), nn.BatchNorm2d(4), nn.ReLU(), nn.Flatten())
    fast = InferenceCopy(_with_batch_statistics(net, seed=3))
    x = torch.rand(2, 3, 6, 6) * 255
    before = fast(x)
    assert torch.allclose(before, net(x).detach(), rtol=1e-4, atol=1e-3)
    optimizer = torch.optim.SGD(net.parameters(), lr=0.1)
    net.train()
    net(x).square().mean().backward()
    optimizer.step()  # in-place: the weights' versions move on
    net.eval()
    after = fast(x)
    assert not torch.allclose(after, before, atol=1e-3)
    assert torch.allclose(after, net(x).detach(), rtol=1e-4, atol=1e-3)
    net.load_state_dict({k: v.clone() * 0.5 if k.endswith("weight") else v.clone() for k, v in net.state_dict().items()})
    assert torch.allclose(fast(x), net(x).detach(), rtol=1e-4, atol=1e-3)
    copied = pickle.loads(pickle.dumps(fast))
    assert copied._copy is None and torch.allclose(copied(x), fast(x), rtol=1e-4, atol=1e-3)


def test_the_place_network_and_the_controller_act_through_their_copies_as_through_the_modules():
    torch.manual_seed(0)
    model = _with_batch_statistics(SiameseNet(channels=[8, 16], embedding_dim=16, hidden=32), seed=4)
    images = np.random.default_rng(0).integers(0, 255, (3, 24, 32, 3)).astype(np.uint8)
    with torch.no_grad():
        direct = model.backbone(torch.from_numpy(images).permute(0, 3, 1, 2).float()).numpy()
    assert model._inference_backbone._copy is None
    assert np.allclose(model.embed(images), direct, atol=1e-4)
    assert model._inference_backbone._copy is not None  # embed went through the copy
    controller = _with_batch_statistics(TopoDLM(height=24, width=32, channels=(8, 16), hidden=32, augment=False), seed=5)
    shrunk = torch.rand(2, 3, 24, 32) * 255
    with torch.no_grad():
        assert torch.allclose(controller._features(shrunk, inference=True), controller._features(shrunk), atol=1e-4)
    fresh = _with_batch_statistics(TopoDLM(height=24, width=32, channels=(8, 16), hidden=32, augment=False), seed=5)
    fresh.act(images[0], 3.0, 0)
    assert fresh._inference_encoder._copy is not None  # the closed loop's call goes through the copy
