"""Running the trained trajectory RNN over a drive of any length (loading it: :func:`topoloc.trajectory.model.load_model`).

The RNN is trained on paths of ``dataset.path_nodes`` map nodes (tens of
tokens); a real drive has hundreds. With ``window`` set, the drive is cut into
windows of ``window`` tokens that start every ``stride`` tokens (the RNN
restarts in each, so its state never runs past the lengths it was trained
on), all run in one batch; step ``t`` takes its output from the oldest window
that covers it, i.e. with between ``window - stride + 1`` and ``window``
tokens of context. ``window: null`` runs one pass over the whole drive.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError


def check_model(map: Any, localizer: str) -> None:
    """Refuse a missing trajectory model, or one trained on a map with another number of roads (one line)."""
    if map.model is None:
        raise InputError("model", f"the {localizer} localizer needs a trained trajectory model")
    num_edges = int(map.model.hparams.num_edges)
    if num_edges != map.graph.num_edges:
        raise InputError("model", f"the model predicts {num_edges} edge classes but the graph has {map.graph.num_edges} "
                                  "edges: a model trained on another map?")


def window_plan(steps: int, window: int | None, stride: int | None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Window start tokens, and per step the index of the window it is read from."""
    if window is None or steps <= window:
        return np.zeros(1, np.int64), np.zeros(steps, np.int64)
    stride = window if stride is None else stride
    if not 1 <= stride <= window:
        raise InputError("localization.rnn.stride", f"must be between 1 and rnn.window ({window}), got {stride}")
    t = np.arange(steps)
    first = np.maximum(0, -(-(t - window + 1) // stride))  # oldest window start s = i * stride with s > t - window
    return np.arange(first.max() + 1, dtype=np.int64) * stride, first


def edge_log_probs(model: Any, tokens: NDArray[np.int64], window: int | None = None, stride: int | None = None,
                   inputs: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
    """``(T, E)`` log-probabilities of the edge classes at every token of one drive (``inputs``: its
    continuous features ``(T, F)`` for a model trained with them)."""
    import torch  # torch only when a model runs: the localizer registry imports this module (and the workflow the registry)

    tokens = np.asarray(tokens, dtype=np.int64)
    steps = len(tokens)
    if steps == 0:
        raise ValueError("no tokens")
    starts, which = window_plan(steps, window, stride)
    length = steps if len(starts) == 1 else int(window)
    pad = int(model.hparams.bins) if hasattr(model, "hparams") else int(tokens.max())
    batch = np.full((len(starts), length), pad, dtype=np.int64)
    dim = int(getattr(model, "hparams", {}).get("feature_dim", 0))
    feats = np.zeros((len(starts), length, dim), np.float32)
    for row, start in enumerate(starts):
        piece = tokens[start:start + length]
        batch[row, :len(piece)] = piece
        if dim and inputs is not None:
            feats[row, :len(piece)] = np.asarray(inputs, np.float32)[start:start + length]
    model.eval()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a few small windows: one thread is fastest, and never waits on a busy core
    try:
        with torch.inference_mode():
            args = (torch.as_tensor(batch), torch.as_tensor(feats)) if dim else (torch.as_tensor(batch),)
            logp = torch.log_softmax(model(*args).float(), dim=-1).numpy()
    finally:
        torch.set_num_threads(threads)
    t = np.arange(steps)
    return logp[which, t - starts[which]]


class OnlineRNN:
    """The windowed RNN of :func:`edge_log_probs`, one token at a time (same outputs).

    A window starts every ``stride`` tokens and runs for ``window`` tokens with its own recurrent state;
    each token's output is read from the oldest window that covers it. ``window=None``: one window.
    The methods are those of :class:`topoloc.localizer.Filter`; the answer is the log-probabilities.
    """

    def __init__(self, model: Any, window: int | None = None, stride: int | None = None) -> None:
        import torch  # see edge_log_probs

        self.model, self.window = model.eval(), window
        self.stride = (window if stride is None else stride) if window is not None else None
        if window is not None and not 1 <= self.stride <= window:
            raise InputError("localization.rnn.stride", f"must be between 1 and rnn.window ({window}), got {self.stride}")
        self._torch = torch
        self.start()

    def start(self) -> None:
        """Forget every token."""
        self.t = 0
        self.windows: dict[int, Any] = {}  # window start -> recurrent state
        self.last: NDArray[np.float32] | None = None

    def update(self, token: int, inputs: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
        """Log-probabilities ``(E,)`` of the edge classes after ``token`` (``inputs``: its continuous features,
        for a model trained with them)."""
        torch = self._torch
        t = self.t
        if not self.windows or (self.window is not None and t % self.stride == 0):
            self.windows[t] = None
        if self.window is not None:
            self.windows = {s: h for s, h in self.windows.items() if s > t - self.window}
        x = torch.as_tensor([[int(token)]])
        out = None
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            with torch.inference_mode():
                if hasattr(self.model, "step_input"):
                    f = None if inputs is None else torch.as_tensor(np.asarray(inputs, np.float32)).reshape(1, 1, -1)
                    embedded = self.model.step_input(x, f)
                else:
                    embedded = self.model.embedding(x)
                for s in sorted(self.windows):
                    features, self.windows[s] = self.model.rnn(embedded, self.windows[s])
                    if out is None:  # the oldest window
                        out = torch.log_softmax(self.model.head(features[0, 0]).float(), dim=-1).numpy()
        finally:
            torch.set_num_threads(threads)
        self.t += 1
        self.last = out
        return out

    def answer(self) -> NDArray[np.float32] | None:
        """The log-probabilities after the last token (None before the first)."""
        return self.last
