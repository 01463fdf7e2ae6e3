"""Example trust-av plug-in: models registered through entry points, installed with pip.

Each model is in its own module and registered in ``pyproject.toml``:
:mod:`trust_av_example_plugin.smoothing` (plan estimator ``ses``).
"""
