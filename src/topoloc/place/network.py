"""The siamese place-recognition network (Cai & Wan, Sec. 3.3), in plain torch, trained with Lightning.

* **Backbone** (:class:`Backbone`, shared by both images): each image is normalised on its own, by default by
  its local contrast (``normalize: local``: minus the 9 x 9 local mean, over the local deviation; ``image``
  standardises the whole image instead): most of a condition's brightness and colour cast drops out. Then a compact
  ResNet-style network: a 3x3 stem with stride 2 and one basic residual block per stage (3x3 convs, batch
  norm, ReLU, stride 2, 1x1 projection shortcut), average pooling to a ``pool`` grid (the layout of the
  scene is kept: a building on the left is not a building on the right), and a linear layer to the
  ``embedding_dim`` embedding. The paper's ResNet50 with ImageNet weights cannot be downloaded here; this
  one trains from scratch, and ``weights`` loads a local state_dict.
* **Head** (:class:`SiameseNet`): the two embeddings concatenated, two fully connected layers, a softmax over
  (different place, same place); cross-entropy loss.
* **Training**: RAdam, learning rate ``lr`` multiplied by ``lr_decay`` every epoch, batch 32 (the paper: 1e-4;
  the default config: 1e-3 for a network trained from scratch in minutes); photometric and small-shift
  augmentation of each image (``augment``).

``forward`` takes a stacked pair tensor ``(N, 2, C, H, W)`` of float pixel values 0..255 and returns the
probabilities ``(N, 2)``: the signature of the logged MLflow model. For retrieval, :meth:`SiameseNet.embed`
embeds images once and :meth:`SiameseNet.same_place` scores embeddings against each other.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn
from torch.nn import functional as F

from topoloc.errors import InputError
from topoloc.fast_inference import InferenceCopy


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with batch norm and a residual shortcut (1x1 projection when the shape changes)."""

    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.shortcut = nn.Identity() if cin == cout and stride == 1 else nn.Sequential(
            nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)), inplace=True)
        out = self.bn2(self.conv2(out))
        return F.relu(out + self.shortcut(x), inplace=True)


def eval_mode(module: nn.Module) -> None:
    """Put ``module`` in eval mode unless it is already (``eval()`` walks every submodule each call: about a
    millisecond a closed-loop step over the controller and the retrieval network)."""
    if module.training:
        module.eval()


def standardize(images: torch.Tensor, eps: float = 1.0) -> torch.Tensor:
    """Per image: subtract each channel's mean, divide by the standard deviation over all pixels (0..255 input)."""
    centred = images - images.mean(dim=(2, 3), keepdim=True)
    std = centred.pow(2).mean(dim=(1, 2, 3), keepdim=True).sqrt()
    return centred / (std + eps)


def box_mean(images: torch.Tensor, size: int) -> torch.Tensor:
    """Mean over the ``size`` x ``size`` neighbourhood of each pixel (edges replicated), from running sums.

    Running sums cost four subtractions per pixel whatever ``size`` is: several times faster on the CPU than
    ``avg_pool2d`` with stride 1, and equal to it within float32 rounding (about 1e-4 of a 0..255 image).
    """
    if size < 1 or size % 2 == 0:
        raise ValueError(f"box size must be odd and positive, got {size}")
    pad = size // 2
    x = F.pad(images, (pad, pad, pad, pad), mode="replicate")
    x = F.pad(x.cumsum(2), (0, 0, 1, 0))
    x = x[:, :, size:] - x[:, :, :-size]
    x = F.pad(x.cumsum(3), (1, 0, 0, 0))
    return (x[..., size:] - x[..., :-size]) / (size * size)


def local_normalize(images: torch.Tensor, size: int = 9, eps: float = 4.0) -> torch.Tensor:
    """Local contrast normalisation: subtract the ``size`` x ``size`` local mean, divide by the local deviation."""
    centred = images - box_mean(images, size)
    return centred / (box_mean(centred * centred, size).clamp_min(0.0).sqrt() + eps)


NORMALIZERS = {"image": standardize, "local": local_normalize}


class Backbone(nn.Module):
    """Image ``(N, C, H, W)`` (0..255) -> embedding ``(N, embedding_dim)`` of L2 norm ``scale``."""

    def __init__(self, in_channels: int = 3, channels: Sequence[int] = (16, 32, 64, 128), embedding_dim: int = 128,
                 pool: Sequence[int] = (1, 4), normalize: str = "local", scale: float = 4.0) -> None:
        super().__init__()
        self.scale = float(scale)
        if normalize not in NORMALIZERS:
            raise ValueError(f"normalize must be one of {sorted(NORMALIZERS)}, got {normalize!r}")
        self.normalize = NORMALIZERS[normalize]
        self.stem = nn.Sequential(nn.Conv2d(in_channels, channels[0], 3, 2, 1, bias=False), nn.BatchNorm2d(channels[0]),
                                  nn.ReLU(inplace=True))
        blocks = [BasicBlock(cin, cout, 2) for cin, cout in zip(channels[:-1], channels[1:])]
        self.stages = nn.Sequential(*blocks)
        self.pool = nn.AdaptiveAvgPool2d(tuple(int(p) for p in pool))
        self.fc = nn.Linear(channels[-1] * int(pool[0]) * int(pool[1]), embedding_dim)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        x = self.stages(self.stem(self.normalize(images)))
        return self.scale * F.normalize(self.fc(torch.flatten(self.pool(x), 1)), dim=1)


def augment(images: torch.Tensor, generator: torch.Generator | None = None, shift_px: int = 4) -> torch.Tensor:
    """Random per-image colour gains, gamma, contrast, sensor noise and a small horizontal shift (0..255 floats)."""
    n, c = images.shape[:2]
    dev = images.device

    def uniform(shape: tuple[int, ...], lo: float, hi: float) -> torch.Tensor:
        return lo + (hi - lo) * torch.rand(shape, generator=generator, device=dev)

    x = (images / 255.0).clamp_min(1e-4) ** torch.exp(uniform((n, 1, 1, 1), -0.5, 0.5))
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    x = (mean + (x - mean) * uniform((n, 1, 1, 1), 0.6, 1.2)) * uniform((n, c, 1, 1), 0.75, 1.25)
    x = x + uniform((n, 1, 1, 1), 0.0, 0.03) * torch.randn(x.shape, generator=generator, device=dev)
    if shift_px:
        shifts = torch.randint(-shift_px, shift_px + 1, (n,), generator=generator, device=dev)
        padded = F.pad(x, (shift_px, shift_px, 0, 0), mode="replicate")
        cols = torch.arange(x.shape[-1], device=dev)[None, :] + shift_px + shifts[:, None]
        x = torch.gather(padded, 3, cols[:, None, None, :].expand(-1, c, x.shape[2], -1))
    return x.clamp(0.0, 1.0) * 255.0


def metric_init(head: nn.Sequential, dim: int, alpha: float = 1.0, beta: float = 4.0) -> None:
    """Start the head as an L1 distance: hidden units ``relu(e1 - e2)`` and ``relu(e2 - e1)``, same-place logit
    ``beta - alpha |e1 - e2|_1`` (the other units and logit start at zero); training then reshapes all of it."""
    first, last = head[0], head[-1]
    if first.out_features < 2 * dim:
        raise ValueError(f"a metric head needs at least {2 * dim} hidden units, got {first.out_features}")
    eye = torch.eye(dim)
    with torch.no_grad():
        first.weight.zero_()
        first.bias.zero_()
        first.weight[:dim] = torch.cat([eye, -eye], dim=1)
        first.weight[dim:2 * dim] = torch.cat([-eye, eye], dim=1)
        last.weight.zero_()
        last.weight[1, :2 * dim] = -alpha
        last.bias.copy_(torch.tensor([0.0, beta]))


class SiameseNet(L.LightningModule):
    """Shared backbone, concatenated embeddings, FC -> ReLU -> FC -> softmax over (different, same)."""

    def __init__(self, in_channels: int = 3, channels: Sequence[int] = (16, 32, 64, 128), embedding_dim: int = 128,
                 pool: Sequence[int] = (1, 4), hidden: int = 256, normalize: str = "local", embedding_scale: float = 4.0,
                 head_init: str = "metric", lr: float = 1e-4, lr_decay: float = 0.95, weight_decay: float = 0.0,
                 augment: bool = True, seed: int = 0) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.backbone = Backbone(in_channels, list(channels), embedding_dim, list(pool), normalize, embedding_scale)
        self.head = nn.Sequential(nn.Linear(2 * embedding_dim, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, 2))
        if head_init == "metric":
            metric_init(self.head, embedding_dim)
        elif head_init != "random":
            raise ValueError(f"head_init must be metric or random, got {head_init!r}")
        self._generator: torch.Generator | None = None
        self._inference_backbone = InferenceCopy(self.backbone)

    # -- inference ---------------------------------------------------------------------------------------
    def forward(self, pairs: torch.Tensor) -> torch.Tensor:
        """Probabilities ``(N, 2)`` (different, same) of a pair tensor ``(N, 2, C, H, W)`` with values 0..255."""
        n = pairs.shape[0]
        emb = self.backbone(pairs.flatten(0, 1).float()).view(n, 2, -1)
        return torch.softmax(self.head(emb.flatten(1)), dim=1)

    def logits(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """Logits ``(N, 2)`` of image batches ``a`` and ``b`` ``(N, C, H, W)``."""
        emb = self.backbone(torch.cat([a, b]).float())
        return self.head(torch.cat(emb.chunk(2), dim=1))

    @torch.no_grad()
    def embed(self, images: NDArray[np.uint8], batch_size: int = 256) -> NDArray[np.float32]:
        """Embeddings ``(n, D)`` of uint8 images ``(n, H, W, C)``."""
        eval_mode(self)
        out = []
        for start in range(0, len(images), batch_size):
            batch = torch.from_numpy(np.ascontiguousarray(images[start:start + batch_size])).permute(0, 3, 1, 2)
            out.append(self._inference_backbone(batch.float().to(self.device)).cpu())
        return torch.cat(out).numpy() if out else np.zeros((0, self.hparams.embedding_dim), np.float32)

    @torch.no_grad()
    def same_place(self, query: NDArray[np.float32], refs: NDArray[np.float32]) -> NDArray[np.float32]:
        """Probability that the place of embedding ``query`` (D,) is that of each row of ``refs`` (m, D)."""
        eval_mode(self)
        q = torch.from_numpy(np.asarray(query, np.float32)).to(self.device).expand(len(refs), -1)
        r = torch.from_numpy(np.asarray(refs, np.float32)).to(self.device)
        return torch.softmax(self.head(torch.cat([q, r], dim=1)), dim=1)[:, 1].cpu().numpy()

    @torch.no_grad()
    def score_matrix(self, queries: NDArray[np.float32], refs: NDArray[np.float32], chunk: int = 64) -> NDArray[np.float32]:
        """P(same place) of every query embedding (n, D) against every reference (m, D): (n, m).

        The first layer of the head acts on the concatenation, so it splits into a query part and a
        reference part computed once each; only the ReLU and the last layer run per pair.
        """
        eval_mode(self)
        first, last, dim = self.head[0], self.head[2], self.hparams.embedding_dim
        q = torch.from_numpy(np.asarray(queries, np.float32)).to(self.device) @ first.weight[:, :dim].T
        r = torch.from_numpy(np.asarray(refs, np.float32)).to(self.device) @ first.weight[:, dim:].T + first.bias
        out = [torch.softmax(last(torch.relu(q[i:i + chunk, None] + r[None])), dim=-1)[..., 1]
               for i in range(0, len(q), chunk)]
        return torch.cat(out).cpu().numpy() if out else np.zeros((0, len(r)), np.float32)

    # -- training ----------------------------------------------------------------------------------------
    def _step(self, batch: Any, stage: str) -> torch.Tensor:
        """Cross-entropy of pairs ``(a[i], b[i])`` with labels (N,), or of all ``(a[i], b[j])`` with labels (N, N).

        A label matrix holds 1 / 0 / -100 (ignored); its loss is the mean over positives and the mean over
        negatives, averaged (the two labels weigh the same however many negatives the batch holds).
        """
        a, b, label = batch[:3]
        a, b = a.permute(0, 3, 1, 2).float(), b.permute(0, 3, 1, 2).float()
        if stage == "train" and self.hparams.augment:
            if self._generator is None:
                self._generator = torch.Generator(device=a.device).manual_seed(int(self.hparams.seed))
            a, b = augment(a, self._generator), augment(b, self._generator)
        if label.ndim == 2:
            n = len(a)
            ea, eb = self.backbone(torch.cat([a, b])).chunk(2)
            logits = self.head(torch.cat([ea[:, None].expand(n, n, -1), eb[None].expand(n, n, -1)], dim=2).flatten(0, 1))
            label = label.flatten()
            ce = F.cross_entropy(logits, label.clamp_min(0), reduction="none")
            pos, neg = label == 1, label == 0
            loss = 0.5 * (ce[pos].mean() if pos.any() else 0.0) + 0.5 * (ce[neg].mean() if neg.any() else 0.0)
            keep = label >= 0
            acc = (logits.argmax(1)[keep] == label[keep]).float().mean()
        else:
            logits = self.logits(a, b)
            loss = F.cross_entropy(logits, label)
            acc = (logits.argmax(1) == label).float().mean()
        opts = {"on_epoch": True, "batch_size": len(a), "add_dataloader_idx": False}
        self.log(f"{stage}/loss", loss, prog_bar=True, on_step=stage == "train", **opts)
        self.log(f"{stage}/acc", acc, prog_bar=stage == "val", on_step=False, **opts)
        return loss

    def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
        return self._step(batch, "train")

    def validation_step(self, batch: Any, batch_idx: int, dataloader_idx: int = 0) -> None:
        """Loader 0: ``val/loss`` / ``val/acc``; loader 1 (items carry a condition index): ``val/acc_<condition>``."""
        if dataloader_idx == 0:
            self._step(batch, "val")
            return
        a, b, label, condition = batch[:4]
        logits = self.logits(a.permute(0, 3, 1, 2).float(), b.permute(0, 3, 1, 2).float())
        correct = (logits.argmax(1) == label).float()
        names = getattr(self, "condition_names", None) or []
        for k in condition.unique().tolist():
            sel = condition == k
            name = names[k] if k < len(names) else str(k)
            self.log(f"val/acc_{name}", correct[sel].mean(), on_epoch=True, batch_size=int(sel.sum()),
                     add_dataloader_idx=False)

    def configure_optimizers(self) -> Any:
        hp = self.hparams
        optimizer = torch.optim.RAdam(self.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
        scheduler = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=hp.lr_decay)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "epoch"}}

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # the names of the val/acc_<condition> metrics travel with the weights (the best checkpoint is reloaded)
        checkpoint["condition_names"] = list(getattr(self, "condition_names", None) or [])

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        self.condition_names = list(checkpoint.get("condition_names", []))

def load_model(path: str | Path) -> SiameseNet:
    """The trained network of a ``train_retrieval`` checkpoint, on the CPU, in eval mode."""
    try:
        model = SiameseNet.load_from_checkpoint(str(path), map_location="cpu")
    except (OSError, RuntimeError, KeyError) as err:
        raise InputError(path, f"not a retrieval model checkpoint ({err})") from err
    return model.eval()
