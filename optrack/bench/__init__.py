"""Benchmarks: speed and accuracy of each part of optrack, measured from above it.

One module per ``optrack bench WHAT`` (:mod:`~optrack.bench.sim`,
:mod:`~optrack.bench.detection`, :mod:`~optrack.bench.tracking`,
:mod:`~optrack.bench.calibration`, :mod:`~optrack.bench.e2e`); each returns
its figures as a dict, and :mod:`optrack.bench.cli` prints them (one JSON
object with ``--json``). The package sits above what it measures (the
simulator, the evaluation, the runtime), so nothing below imports it.
"""
