"""Inference copies of the small convolutional networks the closed loop runs once a step.

At one image a step on one core, the place network's backbone and a controller's image encoder spend a good share
of their time in batch norms, and their convolutions run faster on channels-last tensors. :class:`InferenceCopy`
runs a module through an eval-mode copy of it with each batch norm that only follows a convolution folded into that
convolution's weights (:func:`fold_batch_norms`), in the channels-last layout: the same outputs within float32
rounding (about 1e-6 of an activation), a fifth to a quarter less time (measured in docs/route_following.md,
"Speed"). The copy is made again when the module's weights change (an optimiser step, ``load_state_dict``), so
training in between is safe. Use it only without gradients: the copy is detached from the module's parameters.
"""

from __future__ import annotations

import copy

import torch
from torch import fx, nn
from torch.nn.utils.fusion import fuse_conv_bn_eval


def fold_batch_norms(module: nn.Module) -> fx.GraphModule:
    """An eval-mode copy of ``module`` in which every ``BatchNorm2d`` whose input is a ``Conv2d`` used nowhere else
    is folded into that convolution (the module must trace with :func:`torch.fx.symbolic_trace`)."""
    graph_module = fx.symbolic_trace(copy.deepcopy(module).eval())
    modules = dict(graph_module.named_modules())
    for node in list(graph_module.graph.nodes):
        if node.op != "call_module" or not isinstance(modules[node.target], nn.BatchNorm2d):
            continue
        conv = node.args[0]
        if not (isinstance(conv, fx.Node) and conv.op == "call_module" and isinstance(modules[conv.target], nn.Conv2d)
                and len(conv.users) == 1):
            continue
        parent, _, name = conv.target.rpartition(".")
        setattr(graph_module.get_submodule(parent), name, fuse_conv_bn_eval(modules[conv.target], modules[node.target]))
        node.replace_all_uses_with(conv)
        graph_module.graph.erase_node(node)
    graph_module.graph.lint()
    graph_module.recompile()
    graph_module.delete_all_unused_submodules()
    return graph_module


class InferenceCopy:
    """Calls ``module`` on a batch ``(N, C, H, W)`` through its folded, channels-last copy (module docstring)."""

    def __init__(self, module: nn.Module) -> None:
        self.module = module
        self._copy: nn.Module | None = None
        self._tensors: list[torch.Tensor] = []
        self._key: list[tuple[int, int]] = []

    def __getstate__(self) -> dict:
        return {"module": self.module, "_copy": None, "_tensors": [], "_key": []}  # a pickled model (MLflow): no copy

    def _weights_key(self) -> list[tuple[int, int]]:
        # a tensor's version counts its in-place changes (optimiser steps, load_state_dict); its pointer, a move
        return [(t.data_ptr(), t._version) for t in self._tensors]

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        if self._copy is None or self._weights_key() != self._key:
            self._tensors = [*self.module.parameters(), *self.module.buffers()]
            self._copy = fold_batch_norms(self.module).to(memory_format=torch.channels_last)
            self._key = self._weights_key()
        with torch.no_grad():
            return self._copy(x.contiguous(memory_format=torch.channels_last))
