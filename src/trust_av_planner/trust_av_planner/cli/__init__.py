"""``trust-av``, the project's command line: :mod:`~trust_av_planner.cli.main` builds the
parser from one module per command (``simulate``, ``run``, ``shadow``, ``reproduce``,
``trace-to-bag``, ``train-gru``, ``fit-driver``); shared options live in
:mod:`~trust_av_planner.cli.options`."""
