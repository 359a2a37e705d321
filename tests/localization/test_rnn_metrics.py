"""Windowed RNN runs over long drives, and the localization metrics."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from topoloc.errors import InputError
from topoloc.localization.evaluation import localized_step
from topoloc.localization.rnn import edge_log_probs, window_plan
from topoloc.trajectory.model import TrajectoryRNN, load_model


def test_window_plan_gives_every_step_the_oldest_window():
    starts, which = window_plan(50, 20, 5)
    context = np.arange(50) - starts[which]
    assert starts.tolist() == list(range(0, 35, 5))
    assert context.max() == 19 and context[19:].min() == 15  # between window - stride + 1 and window tokens
    assert window_plan(10, 20, 5)[0].tolist() == [0] and window_plan(50, None, None)[1].tolist() == [0] * 50
    with pytest.raises(InputError, match="stride"):
        window_plan(50, 20, 30)


def test_windowed_outputs_equal_a_fresh_run_on_each_window():
    torch.manual_seed(0)
    model = TrajectoryRNN(20, 7, cell="gru", hidden_size=16, embedding_dim=8)
    tokens = np.random.default_rng(0).integers(0, 20, 45)
    logp = edge_log_probs(model, tokens, window=12, stride=4)
    starts, which = window_plan(45, 12, 4)
    for t in (0, 11, 12, 30, 44):
        s = starts[which[t]]
        with torch.no_grad():
            alone = torch.log_softmax(model(torch.as_tensor(tokens[None, s:t + 1])), -1)[0, -1].numpy()
        assert np.allclose(logp[t], alone, atol=1e-5)
    assert np.allclose(np.exp(logp).sum(axis=1), 1.0, atol=1e-5)
    full = edge_log_probs(model, tokens)  # one pass
    with torch.no_grad():
        assert np.allclose(full, torch.log_softmax(model(torch.as_tensor(tokens[None])), -1)[0].numpy(), atol=1e-5)


def test_localized_step_needs_a_confirmed_stretch():
    distance = 20.0 * np.arange(10)
    correct = np.array([0, 1, 0, 1, 1, 1, 1, 0, 1, 1], bool)
    assert localized_step(correct, distance, confirm_m=60.0) == 3  # 3..6 is right for 60 m
    assert localized_step(correct, distance, confirm_m=80.0) == 8  # only the tail (to the end) qualifies
    assert localized_step(np.zeros(5, bool), distance[:5], 10.0) is None


def test_unknown_model_is_one_line_error(tmp_path):
    with pytest.raises(InputError, match="checkpoint not found"):
        load_model(str(tmp_path / "missing.ckpt"))
    with pytest.raises(InputError, match="no trajectory model at runs:/0123456789abcdef0123456789abcdef/model") as err:
        from mlflow import MlflowClient

        MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}").search_experiments()
        load_model("0123456789abcdef0123456789abcdef", tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    assert "\n" not in str(err.value)
