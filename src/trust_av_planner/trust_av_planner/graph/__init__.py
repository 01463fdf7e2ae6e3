"""trust_av_planner.graph (a regular package, so that setuptools' find_packages installs it)."""
