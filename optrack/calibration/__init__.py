"""Camera and network calibration (OpenPTrack, Munaro et al. 2016, section 4).

* :mod:`~optrack.calibration.board`: the checkerboard, its corners in colour and infrared
  images, the coverage map.
* :mod:`~optrack.calibration.intrinsics`: one camera's intrinsics (OpenCV).
* :mod:`~optrack.calibration.stereo`: a stereo pair's relative pose.
* :mod:`~optrack.calibration.network`: the live calibrator and the global optimisation of
  all camera and board poses (gtsam); :mod:`~optrack.calibration.views` (one view's board
  pose, the tree of relative poses) and :mod:`~optrack.calibration.factors` (the factor
  graph, the floor boards in one plane) are its parts.
* :mod:`~optrack.calibration.session`: a recorded checkerboard session, board-on-floor test.
* :mod:`~optrack.calibration.ground`: the world frame from floor boards or known points.
* :mod:`~optrack.calibration.refinement`: refinement from one walking person (Algorithm 1).
* :mod:`~optrack.calibration.files`: calibration files, OpenPTrack and ROS exports.
* :mod:`~optrack.calibration.printable`: a printable board.
* :mod:`~optrack.calibration.quality`: errors against the truth;
  :mod:`~optrack.calibration.truth`: a recording's true poses and floor views.
* :mod:`~optrack.calibration.synthetic`: synthetic sessions and walks with known truth.
* :mod:`~optrack.calibration.cli`: ``optrack calibrate`` (the command layer).

Submodules are imported where used (gtsam and Open3D take a while to load).
"""
