"""The command-line interface: a thin typer layer over :mod:`dracc.pipeline.analysis` and friends."""

import os

# dracc's linear algebra is small (2x2 and 3x3 covariances, normal equations of a few dozen
# unknowns), so one BLAS thread does it.  Idle OpenBLAS threads spin after each call: on
# a day's log they burnt 0.4 s of CPU that the ingest workers needed (bench_analyze.py).
# Read when numpy loads, so set here, before any command imports it; a user's value wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
