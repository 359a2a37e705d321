"""Route following under appearance change (Cai & Wan), one module per job.

* Routes and lanes: :mod:`.route_planning` (chains of road edges), :mod:`.lane_geometry` (the lane's polyline),
  :mod:`.lane_rasters` (drivable area, corridor, shared lane points), :mod:`.drive_route` (:class:`DriveRoute`:
  the lane with its commands and rasters), :mod:`.routes` (the teach, evaluation and training routes and their
  simulators), :mod:`.camera` (the controller's camera).
* The simulator, expert and demonstrations: :mod:`.simulator`, :mod:`.expert`, :mod:`.demonstrations`.
* The controllers: :mod:`.controller` (Topo-DLM), :mod:`.topo_lp` (Topo-LP), :mod:`.local_path`,
  :mod:`.controller_training` (fit, DAgger rounds, closed-loop check) over :mod:`.on_policy` (the controller at the
  wheel).
* Teach and repeat in closed loop: :mod:`.repeat_routes`, :mod:`.agents`, :mod:`.localization_adapters`,
  :mod:`.episodes`, and the report :mod:`.follow_report`.
* Stages (``run`` only): :mod:`.simulate_demonstrations`, :mod:`.train_controller`, :mod:`.follow_route`;
  :mod:`.config_slices` holds the rules' config slices.
"""
