"""The localization loop on a synthetic sequence with known matches: window search, odometry, relocalization."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.place.topometric_localization import (
    MATCH,
    NO_MATCH,
    ODOMETRY,
    RELOC_FAIL,
    RELOC_OK,
    CorrelationScorer,
    LocalizeSettings,
    correlation_descriptors,
    localize,
    nearest_vertex,
    nearest_vertices,
)

M = 200  # vertices 1 m apart
VERTEX_S = np.arange(M, dtype=float)
DEFAULTS = load(None)["place"]["localize"]  # the schema's: the paper's values


def settings(**changes) -> LocalizeSettings:
    """The loop's settings of the default config, with ``changes``."""
    return LocalizeSettings.from_conf({**DEFAULTS, **changes})


class KnownMatches:
    """Frame t is at vertex t. ``visible`` frames score 0.9 there and 0.1 elsewhere; the others score below
    the threshold everywhere, with their global best at a scattered vertex (or at ``blind_best[t]``)."""

    def __init__(self, visible: set[int], blind_best: dict[int, int] | None = None, peak: float = 0.9) -> None:
        self.visible, self.blind_best, self.peak = visible, blind_best or {}, peak
        self.calls: list[tuple[int, np.ndarray]] = []

    def __call__(self, t: int, idx: np.ndarray) -> np.ndarray:
        self.calls.append((t, idx.copy()))
        scores = np.full(len(idx), 0.1)
        if t in self.visible:
            scores[idx == t] = self.peak
        else:
            scores[idx == self.blind_best.get(t, (t * 37) % M)] = 0.5
        return scores


def test_window_search_odometry_fallback_and_relocalization():
    n = 100
    ds = np.full(n, 1.5)  # odometry 50 % too long: the estimate drifts whenever nothing matches
    visible = set(range(20)) | {40} | set(range(80, n))
    scorer = KnownMatches(visible)
    trace = localize(VERTEX_S, ds, scorer, settings(threshold=0.8, window=15, lost_frames=30,
                                                     reloc_images=5, reloc_span=30))
    # 0-19: every frame searched in its window and matched at the true vertex
    assert trace.event[:20] == [MATCH] * 20 and list(trace.vertex[:20]) == list(range(20))
    # 20-39: no score above the threshold: path integration from the last match
    for t in range(20, 40):
        assert trace.event[t] == NO_MATCH
        assert trace.s[t] == pytest.approx(19 + 1.5 * (t - 19))
        assert trace.vertex[t] == nearest_vertex(VERTEX_S, 19 + 1.5 * (t - 19))
    # 40: the window around the drifted estimate (vertex 50) still holds the truth: matched, drift removed
    assert trace.event[40] == MATCH and trace.vertex[40] == 40
    # 41-69: lost, window search only; 70 = 30 frames after the last match: global relocalization begins
    assert set(trace.event[41:70]) == {NO_MATCH}
    assert trace.event[70] == RELOC_FAIL  # the last five images' global bests are scattered
    assert trace.event[70:84] == [RELOC_FAIL] * 14  # retried at every search frame, odometry meanwhile
    assert trace.s[83] == pytest.approx(40 + 1.5 * 43)
    # 84: frames 80-84 agree (spread 4 <= 30): relocalized at the current frame's best vertex
    assert trace.event[84] == RELOC_OK and trace.vertex[84] == 84 and trace.s[84] == 84.0
    # 85-: window search again, matched
    assert set(trace.event[85:]) == {MATCH} and list(trace.vertex[85:]) == list(range(85, n))
    assert trace.count(RELOC_OK) == 1 and trace.count(RELOC_FAIL) == 14
    # window search scores exactly the vertices within 15 of the estimate; relocalization scores all of them
    for t, idx in scorer.calls:
        assert len(idx) == M or len(idx) <= 31
    t40 = [idx for t, idx in scorer.calls if t == 40 and len(idx) <= 31][0]
    v = nearest_vertex(VERTEX_S, 19 + 1.5 * 21)
    assert list(t40) == list(range(v - 15, v + 16))
    # each frame is matched globally at most once (cached across attempts)
    global_frames = [t for t, idx in scorer.calls if len(idx) == M]
    assert len(global_frames) == len(set(global_frames)) and set(global_frames) == set(range(66, 85))


def test_true_vertex_outside_the_window_is_not_found():
    ds = np.full(40, 3.0)  # the estimate runs away: after a few frames the truth is outside the window
    trace = localize(VERTEX_S, ds, KnownMatches({0} | set(range(10, 40))), settings(window=5))
    assert trace.event[0] == MATCH
    assert trace.vertex[9] == 27  # 9 frames x 3 m, no match in 1..9
    # frame 10 is at vertex 10, the window is 30 +- 5: no match, the estimate keeps drifting
    assert trace.event[10] == NO_MATCH


def test_relocalization_span_limit_and_threshold_are_strict():
    # frames 0..34 blind; frames 30..34 have global bests spread by exactly 30, then by 31
    for spread, expected in ((30, RELOC_OK), (31, RELOC_FAIL)):
        best = {30: 100, 31: 100 + spread, 32: 110, 33: 105, 34: 101}
        trace = localize(VERTEX_S, np.ones(35), KnownMatches(set(), best), settings(lost_frames=30))
        assert trace.event[34] == expected
        assert trace.event[30] == RELOC_FAIL  # the global bests of frames 26..29 are scattered
    # a score equal to the threshold is not accepted; above it is
    at = localize(VERTEX_S, np.ones(5), KnownMatches(set(range(5)), peak=0.8), settings(threshold=0.8))
    assert set(at.event) == {NO_MATCH}
    above = localize(VERTEX_S, np.ones(5), KnownMatches(set(range(5)), peak=0.81), settings(threshold=0.8))
    assert set(above.event) == {MATCH}


def test_search_at_a_fixed_rate():
    trace = localize(VERTEX_S, np.ones(12), KnownMatches(set(range(12))), settings(search_every=3))
    assert trace.event == [MATCH if t % 3 == 0 else ODOMETRY for t in range(12)]
    assert np.isnan(trace.score[1]) and trace.score[3] == pytest.approx(0.9)


class FalsePeak:
    """Frame t is at vertex t (score 0.9 there, 0.1 elsewhere), except frame ``bad``, whose peak (0.99) is at
    vertex ``bad + 10`` (a look-alike place ten metres on) while it scores 0.5 at its true vertex."""

    def __init__(self, bad: int) -> None:
        self.bad = bad

    def __call__(self, t: int, idx: np.ndarray) -> np.ndarray:
        scores = np.full(len(idx), 0.1)
        if t == self.bad:
            scores[idx == t] = 0.5
            scores[idx == t + 10] = 0.99
        else:
            scores[idx == t] = 0.9
        return scores


def test_sequence_scoring_rejects_a_single_false_peak():
    ds = np.ones(30)
    single = localize(VERTEX_S, ds, FalsePeak(20), settings(window=15, sequence_frames=1))
    assert single.event[20] == MATCH and single.vertex[20] == 30  # the paper's search jumps to the look-alike
    seq = localize(VERTEX_S, ds, FalsePeak(20), settings(window=15, sequence_frames=3))
    # the candidate 30 scores (0.99 + 0.1 + 0.1) / 3 with frames 19 and 18 behind it; the truth (0.5 + 0.9 + 0.9) / 3,
    # the best but under the threshold: no jump, odometry keeps the estimate at the truth
    assert seq.event[20] == NO_MATCH and seq.vertex[20] == 20 and seq.score[20] == pytest.approx(2.3 / 3)
    assert list(seq.vertex) == list(range(30))
    assert seq.event[20:23] == [NO_MATCH] * 3 and seq.count(MATCH) == 27  # frames 21, 22 still see frame 20
    # the first frames use the frames that exist (frame 0 alone, frame 1 with frame 0)
    assert seq.score[0] == pytest.approx(0.9) and seq.score[1] == pytest.approx(0.9)


def test_nearest_vertices_matches_nearest_vertex():
    vertex_s = np.array([0.0, 0.7, 2.0, 2.1, 5.0])
    s = np.array([-1.0, 0.0, 0.35, 0.36, 1.9, 2.06, 4.0, 9.0])
    assert list(nearest_vertices(vertex_s, s)) == [nearest_vertex(vertex_s, v) for v in s]


def test_correlation_baseline_scores():
    rng = np.random.default_rng(0)
    images = rng.integers(0, 255, (4, 48, 160, 3), dtype=np.uint8)
    desc = correlation_descriptors(images, (32, 10))
    assert desc.shape == (4, 320) and np.allclose(np.linalg.norm(desc, axis=1), 1.0, atol=1e-5)
    brighter = np.clip(images.astype(int) * 0.5 + 60, 0, 255).astype(np.uint8)  # same image, other exposure
    scores = CorrelationScorer(correlation_descriptors(brighter, (32, 10)), desc)(2, np.arange(4))
    assert int(np.argmax(scores)) == 2 and scores[2] > 0.99


def test_bad_settings_name_the_key():
    with pytest.raises(InputError, match=r"^place.localize.window: "):
        settings(window=0)
    with pytest.raises(InputError, match=r"^place.localize.sequence_frames: "):
        settings(sequence_frames=0)
    with pytest.raises(InputError, match=r"^place.localize.reloc_span: "):
        settings(reloc_span=-1)
    with pytest.raises(InputError, match=r"^map: "):
        localize(np.array([]), np.ones(3), KnownMatches(set()), settings())
