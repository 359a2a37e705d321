"""Where the vehicle stands against a teach image: the pose that best warps the road surface of one into the other.

Visual teach and repeat (Furgale & Barfoot) steers by the live image's offset from the image the teach drive took
at the same place. Here the offset is found on the ground plane, which the controller's camera sees from
``camera_height`` metres up: a pixel ``(u, v)`` below the horizon of the teach image is the ground point ``X = f h /
(v - cy)`` ahead and ``Y = -(u - cx) X / f`` to the left. For a pose of the live camera in the teach camera's frame
(``forward_m``, ``left_m`` and ``yaw``, counter-clockwise), each such point projects to a pixel of the live image;
the pose whose projections best match is the answer. A match is the normalised cross-correlation of the horizontal
and vertical intensity gradients (so a change of light or weather that keeps the edges of the lane markings, kerbs
and crossings keeps the score) at the :data:`POINTS` ground pixels of the teach image with the strongest gradients,
up to ``max_range_m`` ahead.

The search is a grid, then a grid a step wide around its best (:class:`AlignmentSearch`): from no prior, +-3 m
ahead, +-2 m aside and +-10 deg; around a prior (:class:`PoseTracker`: the last pose moved by the vehicle's model),
+-0.6 m, +-0.4 m and +-2 deg. Every grid is scored at once (one bilinear lookup per hypothesis and point, ``cv2.remap``):
about 2 ms a match around a prior on the 160 x 72 camera, 30 ms from none. Ahead is the weakest of the three (a straight road
with evenly dashed lines looks alike a dash further on); aside and heading are what a path follower needs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from topoloc.drive.local_path import chain_frame
from topoloc.drive.simulator import Control, VehicleSpec, VehicleState, step_vehicle
from topoloc.render.rig import StereoRig

#: Ground pixels of a teach image scored per hypothesis.
POINTS = 300
#: How a vertex's heading counts against its distance when the tracker picks the vertex nearest its pose (m per deg):
#: where the teach drive turned slowly, many vertices lie within a metre, told apart by their heading.
HEADING_M_PER_DEG = 0.1
#: How far ahead and behind the best pose :meth:`GroundAligner.forward_peak` scores the match again (m).
FORWARD_PROBE_M = 0.5
#: The least :meth:`GroundAligner.forward_peak` for a tracked match to move the pose along the road; by default none does,
#: and the position along the road is the vehicle model's (a search without a prior still sets it). On a straight road
#: with unbroken lines a teach view a little further on matches as well: with every match moving it the pose drifted
#: up to 7 m along the default teach route (across the road it stayed within 0.1 m); with 0.02-0.05, 0.5-1.7 m on
#: average against 0.3-0.4 m with none. The simulator's odometry is exact; a vehicle whose odometry drifts along the
#: road would want a finite value.
MIN_FORWARD_PEAK = float("inf")
#: Share of the gap along the chain between the tracker's pose and the localizer's vertex closed at each step (the
#: position along the road otherwise the model's), and the largest gap that counts (m): the teach drive's odometry
#: scales the chain (``place.odometry_noise.scale_error``: 3 % by default), so the model's distances fall behind or run
#: ahead of the chain's by that share of the distance driven; the localizer's vertex does not.
ALONG_GAIN = 0.1
ALONG_GATE_M = 10.0
#: Only where the chain runs straight: within ``ALONG_STRAIGHT_M`` before and after the vertex it turns less than
#: ``ALONG_STRAIGHT_DEG``. In a turn the place localizer is least sure where along the chain it is, and the turn itself
#: sets the position along the road before it right (that is across the road after it).
ALONG_STRAIGHT_M = 10.0
ALONG_STRAIGHT_DEG = 15.0
#: Share of the way from the pose the vehicle's model predicts to a trusted tracked match's that the pose moves, across
#: the road and in heading (a search without a prior sets it whole). Between matches the model moves as the vehicle
#: does; in a turn, or at night, a match over ``min_score`` is now and then 1-2 m off across the road, and one such
#: match took the pose out of the next search's reach (Heidelberg's roundabout and U-turn routes at night:
#: docs/route_following.md, "What fails on Heidelberg at night").
MATCH_GAIN = 0.3
#: Rows below the horizon skipped: they see the ground too far away to place it.
HORIZON_MARGIN_PX = 3.0

#: A teach image's ground points ``(K, 2)`` (m ahead, m left) and their gradients ``(2K,)`` (:meth:`GroundAligner.reference`).
Reference = tuple[NDArray[np.float64], NDArray[np.float64]]
#: A live image's horizontal and vertical gradients (:func:`gradients`).
Gradients = tuple[NDArray[np.float32], NDArray[np.float32]]


@dataclass(frozen=True)
class Alignment:
    """The live camera's pose in the teach camera's frame (m ahead, m to the left, rad counter-clockwise) and the
    match's score (normalised cross-correlation of gradients, -1 .. 1)."""

    forward_m: float
    left_m: float
    yaw: float
    score: float


@dataclass(frozen=True)
class AlignmentSearch:
    """The grid searched from no prior (half-widths in m, m, deg, and steps) and around a prior."""

    forward_m: float = 3.0
    left_m: float = 2.0
    yaw_deg: float = 10.0
    coarse_steps: tuple[int, int, int] = (13, 17, 11)
    track_half: tuple[float, float, float] = (0.6, 0.4, 2.0)
    track_steps: tuple[int, int, int] = (3, 7, 7)
    refine_steps: int = 3


def gradients(image: NDArray[np.uint8]) -> Gradients:
    """Horizontal and vertical central-difference gradients of the image's mean over its channels."""
    gray = image.astype(np.float32).mean(axis=2) if image.ndim == 3 else image.astype(np.float32)
    gx = np.zeros_like(gray)
    gy = np.zeros_like(gray)
    gx[:, 1:-1] = gray[:, 2:] - gray[:, :-2]
    gy[1:-1] = gray[2:] - gray[:-2]
    return gx, gy


class GroundAligner:
    """Aligns live images to teach images of one camera (see the module docstring)."""

    def __init__(self, rig: StereoRig, max_range_m: float = 25.0, search: AlignmentSearch = AlignmentSearch()) -> None:
        self.rig, self.search = rig, search
        v, u = np.mgrid[0:rig.height, 0:rig.width].astype(np.float64)
        below = v > rig.cy + HORIZON_MARGIN_PX
        ahead = np.where(below, rig.f * rig.camera_height / np.maximum(v - rig.cy, 1e-9), np.inf)
        self._ground = below & (ahead <= float(max_range_m))
        self._x = ahead
        self._y = -(u - rig.cx) * ahead / rig.f

    def reference(self, teach_image: NDArray[np.uint8]) -> Reference:
        """The teach image's ground points ``(K, 2)`` (m ahead, m left) with the strongest gradients and their
        gradients ``(2K,)`` (what :meth:`align` compares; compute once per teach image)."""
        gx, gy = gradients(teach_image)
        strength = np.where(self._ground, np.hypot(gx, gy), -1.0).ravel()
        pick = np.argpartition(strength, -POINTS)[-POINTS:] if len(strength) > POINTS else np.arange(len(strength))
        pick = pick[strength[pick] > 0]
        points = np.column_stack([self._x.ravel()[pick], self._y.ravel()[pick]])
        return points, np.concatenate([gx.ravel()[pick], gy.ravel()[pick]]).astype(np.float64)

    def scores(self, reference: Reference, live: Gradients,
               poses: NDArray[np.float64]) -> NDArray[np.float64]:
        """The match score of each pose ``(H, 3)`` (m ahead, m left, rad) of the live camera (its gradients ``live``)."""
        points, ref = reference
        rig = self.rig
        poses = poses.astype(np.float32)
        px, py = points[:, 0].astype(np.float32), points[:, 1].astype(np.float32)
        c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
        dx, dy = px[None, :] - poses[:, 0:1], py[None, :] - poses[:, 1:2]
        x, y = c * dx + s * dy, c * dy - s * dx
        seen = x > 0.5
        inv = 1.0 / np.where(seen, x, 1.0)
        u = rig.cx - rig.f * y * inv
        v = rig.cy + rig.f * rig.camera_height * inv
        seen &= (u >= 0) & (u <= rig.width - 1.001) & (v >= 0) & (v <= rig.height - 1.001)
        mask = seen.astype(np.float32)
        # bilinear samples of both gradients at every pose's projections (OpenCV: 1/32 px weights, 2.5x numpy's speed)
        b = cv2.remap(np.dstack(live).astype(np.float32), u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT)
        b *= mask[..., None]
        a = ref.astype(np.float32).reshape(2, -1).T  # (K, 2): the horizontal and the vertical gradient per point
        n = 2.0 * mask.sum(axis=1)
        ab, bb, sb = np.einsum("hkc,kc->h", b, a), np.einsum("hkc,hkc->h", b, b), b.sum(axis=(1, 2))
        aa, sa = mask @ (a * a).sum(axis=1), mask @ a.sum(axis=1)
        n_safe = np.maximum(n, 1.0)
        am, bm = sa / n_safe, sb / n_safe
        ab, aa, bb = ab - n * am * bm, aa - n * am ** 2, bb - n * bm ** 2
        ncc = ab / np.sqrt(np.maximum(aa * bb, 1e-9))
        return np.where(n >= 0.5 * len(ref), ncc, -1.0)  # half the points out of view: no answer

    def _best(self, reference: Reference, live: Gradients,
              centre: NDArray[np.float64], half: NDArray[np.float64], steps: tuple[int, int, int]) -> tuple[NDArray[np.float64], float]:
        axes = [c + np.linspace(-h, h, n) if n > 1 else np.array([c]) for c, h, n in zip(centre, half, steps)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        score = self.scores(reference, live, grid)
        k = int(np.argmax(score))
        return grid[k], float(score[k])

    def align(self, reference: Reference, live_image: NDArray[np.uint8] | Gradients,
              prior: tuple[float, float, float] | None = None) -> Alignment:
        """The live image's pose against a teach image's :meth:`reference`: a grid from no prior, or around ``prior``
        (m ahead, m left, rad), then a finer grid around the best (``live_image``: the image, or its
        :func:`gradients`)."""
        live = live_image if isinstance(live_image, tuple) else gradients(live_image)
        search = self.search
        if prior is None:
            half = np.array([search.forward_m, search.left_m, np.radians(search.yaw_deg)])
            steps = search.coarse_steps
            centre = np.zeros(3)
        else:
            half = np.array([search.track_half[0], search.track_half[1], np.radians(search.track_half[2])])
            steps = search.track_steps
            centre = np.asarray(prior, float)
        best, _ = self._best(reference, live, centre, half, steps)
        spacing = 2.0 * half / np.maximum(np.array(steps) - 1, 1)
        best, score = self._best(reference, live, best, spacing, (search.refine_steps,) * 3)
        return Alignment(float(best[0]), float(best[1]), float(best[2]), score)

    def forward_peak(self, reference: Reference, live_image: NDArray[np.uint8] | Gradients, found: Alignment) -> float:
        """How much better ``found`` matches than the same pose :data:`FORWARD_PROBE_M` ahead or behind (near 0 where
        the road looks alike along it; ``live_image`` as :meth:`align` takes it)."""
        best = np.array([found.forward_m, found.left_m, found.yaw])
        probes = best + np.array([[-FORWARD_PROBE_M, 0.0, 0.0], [FORWARD_PROBE_M, 0.0, 0.0]])
        live = live_image if isinstance(live_image, tuple) else gradients(live_image)
        return found.score - float(self.scores(reference, live, probes).max())


class PoseTracker:
    """The vehicle's pose in the topometric map's chain (its coordinates, ``TopometricMap.xy``) during one repeat drive.

    At each step the last estimate is moved by the vehicle's model (:func:`topoloc.drive.simulator.step_vehicle`)
    with the control the agent gave and the measured speed; every ``align_every`` steps the image corrects it: the
    vertex to align against is the one nearest that
    prior (by position, and by heading at :data:`HEADING_M_PER_DEG`) from ``behind_m`` before the last one to
    ``ahead_m`` after it; the live image is aligned against that vertex's teach image (``teach_image(vertex)``, the
    camera at the vertex's pose on the teach drive) around the prior, and when the match scores at least ``min_score``
    the pose moves :data:`MATCH_GAIN` of the way to it across the road and in heading (a turn the teach camera saw
    differently, a crossing whose markings it did not see, keep the prior); along the road only where the match peaks
    there (``min_forward_peak``). Along the road
    the pose is also drawn each step towards the place localizer's vertex, by ``along_gain`` of the gap when the gap
    is within ``along_gate_m`` and the chain runs straight there (:data:`ALONG_STRAIGHT_DEG`): the chain is the teach
    drive's odometry, so its metres are the model's scaled by the teach drive's odometry error, and the localizer
    places the vehicle on the chain itself. The place localizer's vertex also starts it: at the first step, and after
    ``relocalize_steps`` steps whose matches stayed below ``min_score``, the tracker searches without a prior at the
    localizer's vertex; that answer too counts only with a score of ``min_score`` (the first step without one takes
    the vertex's own pose). While it tracks, the tracker's vertex is :attr:`vertex`: a place localizer a few metres
    off moves it along the road only by a share of the gap, and never across it.
    """

    def __init__(self, aligner: GroundAligner, xy: NDArray[np.float64], teach_image: Callable[[int], NDArray[np.uint8]],
                 spec: VehicleSpec, min_score: float = 0.5, relocalize_steps: int = 10, behind_m: float = 2.0,
                 ahead_m: float = 5.0, align_every: int = 2, min_forward_peak: float = MIN_FORWARD_PEAK,
                 along_gain: float = ALONG_GAIN, along_gate_m: float = ALONG_GATE_M) -> None:
        self.aligner, self.xy, self.teach_image, self.spec = aligner, np.asarray(xy, float), teach_image, spec
        self.along_gain, self.along_gate_m = float(along_gain), float(along_gate_m)
        self.min_score, self.relocalize_steps = float(min_score), int(relocalize_steps)
        self.behind_m, self.ahead_m, self.align_every = float(behind_m), float(ahead_m), max(1, int(align_every))
        self.min_forward_peak = float(min_forward_peak)
        self._since = 0
        self._references: dict[int, Reference] = {}
        self._frames: dict[int, tuple[NDArray[np.float64], float]] = {}
        self._straights: dict[int, bool] = {}
        self._arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.xy, axis=0).T))])
        self.state: VehicleState | None = None
        self.vertex = -1
        self.score, self._weak = float("nan"), 0

    def reference(self, vertex: int) -> Reference:
        """The teach image's ground points of ``vertex`` (computed once)."""
        if vertex not in self._references:
            self._references[vertex] = self.aligner.reference(self.teach_image(vertex))
        return self._references[vertex]

    def frame(self, vertex: int) -> tuple[NDArray[np.float64], float]:
        """Vertex ``vertex``'s frame on the chain (:func:`topoloc.drive.local_path.chain_frame`, computed once)."""
        if vertex not in self._frames:
            self._frames[vertex] = chain_frame(self.xy, vertex)
        return self._frames[vertex]

    def _nearest_vertex(self, state: VehicleState) -> int:
        """The vertex whose teach pose is nearest ``state``'s camera, around the last vertex."""
        near = np.flatnonzero((self._arc >= self._arc[self.vertex] - self.behind_m)
                              & (self._arc <= self._arc[self.vertex] + self.ahead_m))
        centre = state.centre(self.spec)
        cost = [float(np.hypot(*(centre - self.frame(v)[0]))) + HEADING_M_PER_DEG
                * abs(np.degrees((state.yaw - self.frame(v)[1] + np.pi) % (2 * np.pi) - np.pi)) for v in near]
        return int(near[int(np.argmin(cost))])

    def _at_arc(self, arc: float) -> int:
        """The vertex whose arc along the chain is nearest ``arc``."""
        k = int(np.clip(np.searchsorted(self._arc, arc), 1, len(self._arc) - 1))
        return k - 1 if arc - self._arc[k - 1] < self._arc[k] - arc else k

    def _straight(self, vertex: int) -> bool:
        """Whether the chain turns by less than :data:`ALONG_STRAIGHT_DEG` from ``ALONG_STRAIGHT_M`` before the vertex
        to as far after it."""
        if vertex not in self._straights:
            here = float(self._arc[vertex])
            before, after = (self.frame(self._at_arc(here + d))[1] for d in (-ALONG_STRAIGHT_M, ALONG_STRAIGHT_M))
            self._straights[vertex] = abs((after - before + np.pi) % (2 * np.pi) - np.pi) < np.radians(ALONG_STRAIGHT_DEG)
        return self._straights[vertex]

    def _pull_along(self, vertex: int) -> None:
        """Move the pose along the chain towards ``vertex`` (see the class docstring), where the chain runs straight."""
        assert self.state is not None
        if not self._straight(self.vertex):
            return
        origin, yaw = self.frame(self.vertex)
        c, s = np.cos(yaw), np.sin(yaw)
        d = self.state.centre(self.spec) - origin
        gap = float(self._arc[vertex] - (self._arc[self.vertex] + c * d[0] + s * d[1]))
        if abs(gap) <= self.along_gate_m:
            shift = self.along_gain * gap
            self.state = replace(self.state, x=self.state.x + shift * c, y=self.state.y + shift * s)

    def update(self, image: NDArray[np.uint8], speed: float, vertex: int, control: Control | None) -> VehicleState:
        """The pose after the last ``control`` (None on the first step), seeing ``image`` at ``speed``, the place
        localizer at ``vertex``: the rear axle's position and the heading in the chain's coordinates."""
        spec = self.spec
        tracking = self.state is not None and control is not None and self._weak < self.relocalize_steps
        if self.state is not None and control is not None:
            self.state = replace(step_vehicle(self.state, control, spec), v=float(speed))
        if tracking:
            assert self.state is not None
            if self.along_gain > 0:
                self._pull_along(int(vertex))
            self.vertex = self._nearest_vertex(self.state)
            self._since += 1
            if self._since < self.align_every:  # the model's prediction alone between matches
                return self.state
        else:
            self.vertex, self._weak = int(vertex), 0
        origin, yaw = self.frame(self.vertex)
        c, s = np.cos(yaw), np.sin(yaw)
        prior = None
        if tracking:
            assert self.state is not None
            d = self.state.centre(spec) - origin
            prior = (c * d[0] + s * d[1], -s * d[0] + c * d[1], (self.state.yaw - yaw + np.pi) % (2 * np.pi) - np.pi)
        live = gradients(image)  # once for the match and its forward peak
        found = self.aligner.align(self.reference(self.vertex), live, prior)
        self.score, self._since = found.score, 0
        if found.score >= self.min_score or self.state is None:
            trusted = found.score >= self.min_score
            forward, left, turn = (found.forward_m, found.left_m, found.yaw) if trusted else (0.0, 0.0, 0.0)
            if prior is not None and (np.isinf(self.min_forward_peak) or self.aligner.forward_peak(
                    self.reference(self.vertex), live, found) < self.min_forward_peak):
                forward = prior[0]  # a road that looks alike a little further on: the model's along-track estimate
            if prior is not None:
                left = prior[1] + MATCH_GAIN * (left - prior[1])
                turn = prior[2] + MATCH_GAIN * ((turn - prior[2] + np.pi) % (2 * np.pi) - np.pi)
            heading = yaw + turn
            centre = origin + np.array([c * forward - s * left, s * forward + c * left])
            h = 0.5 * spec.wheelbase_m
            delta = 0.0 if self.state is None else self.state.delta
            self.state = VehicleState(centre[0] - h * np.cos(heading), centre[1] - h * np.sin(heading), float(heading),
                                      float(speed), delta)
        self._weak = 0 if found.score >= self.min_score else self._weak + 1
        return self.state
