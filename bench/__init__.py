"""Benchmarks of sensor_comp: ``./run bench`` runs them all (see README)."""

import os

# Before numpy loads, also when a benchmark module is run directly: small solves run 30x
# slower when BLAS threads fight for two cores.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
