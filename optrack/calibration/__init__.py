"""Camera and network calibration (OpenPTrack, Munaro et al. 2016, section 4).

* :mod:`~optrack.calibration.board`: the checkerboard, its corners in colour and infrared
  images, the coverage map.
* :mod:`~optrack.calibration.intrinsics`: one camera's intrinsics (OpenCV).
* :mod:`~optrack.calibration.network`: the live tree and the global optimisation of all
  camera and board poses (gtsam), the floor boards in one plane.
* :mod:`~optrack.calibration.session`: a recorded checkerboard session, board-on-floor test.
* :mod:`~optrack.calibration.refinement`: refinement from one walking person (Algorithm 1).
* :mod:`~optrack.calibration.files`: calibration files, OpenPTrack and ROS exports.
* :mod:`~optrack.calibration.printable`: a printable board.
* :mod:`~optrack.calibration.quality`: errors against the truth.
* :mod:`~optrack.calibration.synthetic`: synthetic sessions and walks with known truth.
* :mod:`~optrack.calibration.commands`, :mod:`~optrack.calibration.bench`: the CLI.

Submodules are imported where used (gtsam and Open3D take a while to load).
"""
