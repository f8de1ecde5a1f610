"""Whole-body skeleton tracking (MDCA): body model, likelihood, annealed particle filter."""

import numba

# The parallel kernels' threading layer: OpenMP, as numba picks after trying TBB; the
# system's TBB (2021.5 here) is older than numba accepts, and trying it first printed a
# warning in front of every user of the skeleton (the same layer, the same results).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
