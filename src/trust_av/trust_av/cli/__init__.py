"""``trust-av``, the project's command line: :mod:`~trust_av.cli.main` builds the
parser from one module per command (``simulate``, ``run``, ``shadow``, ``reproduce``,
``trace-to-bag``, ``train-gru``, ``fit-driver``); shared options live in
:mod:`~trust_av.cli.options`.

One BLAS thread per process unless the user says otherwise: the project runs in parallel
by processes (the graph's nodes, the sweep's workers), its matrices are a few dozen rows,
and OpenBLAS starts an idle worker thread per core that spins while numpy loads (about
0.1 CPU-s per process here, seven processes per graph run). Set before numpy is imported;
the graph's nodes and the sweep's workers inherit it.
"""

import os

__all__: list[str] = []

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
