"""The metric filter: a Bayes filter over positions on directed roads, driven by the odometry itself.

After Brubaker, Geiger and Urtasun ("Lost! Leveraging the crowd for probabilistic visual
self-localization", CVPR 2013; PAMI 2016), on our cells (:mod:`topoloc.localization.metric.cell_grid`):

* **Input**: the odometry as planar poses (position and yaw in any frame; the filter never uses
  the frame's orientation or origin). It is cut into *steps*: each time the odometry has driven
  ``cell_m`` metres further along its heading (forward) or back (reversing) one step is taken,
  with the odometry's yaw at that moment. A vehicle that stands still makes no step.
* **State**: a probability per cell, and per cell a belief about the *heading offset* ``theta``
  between the odometry frame and the map (a von Mises distribution: mean and concentration), plus
  one *off-map* state for "on no road of this map".
* **Motion**: a forward step moves every cell ``cell_m`` along the road network (onto every road
  that may follow at a node; one-way roads respected; with ``branches`` ``walks`` each keeps the whole
  probability and the filter's total is kept, so every walk is a priori as likely and a road past more side
  roads is not less likely than a look-alike without them; ``equal``: equal shares; back onto the same road
  where ``u_turns`` allows, at ``u_turn_weight`` of another way's share, sweeping either way), blurred by ``step_jitter``
  (the share that moves zero or two cells: the odometry's scale error); a backward step moves
  along the roads that lead into the cell. Where several cells flow into one, their ``theta``
  beliefs merge (moment matching on the circle); ``theta`` diffuses by ``offset_drift_deg`` per
  square root of 100 m (heading drift of the odometry and slowly varying map error), and by
  ``node_offset_deg`` more through a node (each road of a real map errs its own way).
* **Evidence**: the odometry's yaw against the map road's heading at the cell plus ``theta``:
  von Mises with the spread ``heading_sigma_deg`` (plus, on a turn chain, ``turn_sigma_share`` of
  the turn angle at the node, fading out towards the ends of the turn: vehicles round a corner
  more or less widely than the modelled sweep; with ``bend_spread``, the default, a bend inside a road, a
  vertex of its polyline, widens it the same way, so a turn at a junction and the same bend inside a road
  weigh alike), mixed with a uniform ``floor``; with ``turn_spread: tolerance`` the density keeps a straight
  road's peak wherever it is widened. Curves therefore count as much as corners, and driving straight
  through an intersection gives no false turn. Each observation also sharpens ``theta``.
* **Off the map**: the off-map state predicts the heading without a map: the last one plus the
  noise of two observations (times ``offmap_spread``), or, with ``offmap_turn_prob``, anything (a turn). It wins where the
  drive turns as no road does and loses where a road explains the turn; mass moves there with
  ``leave_prob`` per step and comes back, spread over the whole map, with ``enter_prob``. A drive
  the map cannot explain ends there (low confidence) instead of collapsing onto a wrong road, and
  is found again when it returns.

* **Scale**: once the belief is no longer broad it splits into ``scale_classes`` groups of odometry
  scale error up to ``scale_error_max``, each moving ``1 / (1 + s)`` cells a step
  (:mod:`topoloc.localization.metric.dense_filter`), so lengths count even when the odometry's are off
  by a few percent.

The online answer after each step is the road (undirected edge) with the largest probability,
its best cell (position) and that probability (confidence). The filter also traces a consistent
path back (:meth:`~topoloc.localization.metric.dense_filter.MetricFilter.path`).

The modules of this package:

* :mod:`~topoloc.localization.metric.odometry_steps`: the input, the odometry cut into steps of ``cell_m``;
* :mod:`~topoloc.localization.metric.lane_chains`: the chains of a map, road middles and turns through nodes;
* :mod:`~topoloc.localization.metric.cell_grid`: the chains cut into cells, and how a drive moves between them
  (shared with the token HMM baseline, :mod:`topoloc.localization.hmm`);
* :mod:`~topoloc.localization.metric.merged_duals`: a second reading of the map, its dual carriageways as one road
  each (``merge_duals_m``);
* :mod:`~topoloc.localization.metric.map_model`: the settings and the model of a map, built once: the motion
  model (step transitions) and the measurement model (heading evidence, off the map);
* :mod:`~topoloc.localization.metric.von_mises`: the heading-offset belief's circular statistics;
* :mod:`~topoloc.localization.metric.dense_filter`: the belief over every cell, for one or many starts;
* :mod:`~topoloc.localization.metric.trace`: a filter's path traced back through its record of the steps;
* :mod:`~topoloc.localization.metric.city_filter`: the city-scale variant (coarse cells while the belief is
  broad);
* :mod:`~topoloc.localization.metric.restart`: filters that race a fresh one after losing their track
  (``restart``, on by default).

Every filter follows :class:`topoloc.localizer.Filter`; the registered localizer ``metric`` is the adapter
:mod:`topoloc.localizers.metric`.
"""
