"""Suite-wide settings: one BLAS thread (small solves, 2 cores), no display for plots."""

import os

# Before numpy loads: BLAS threads fighting for two cores make small solves 30x slower.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('MPLBACKEND', 'Agg')
