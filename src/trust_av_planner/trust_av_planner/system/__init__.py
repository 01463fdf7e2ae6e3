"""trust_av_planner.system (a regular package, so that setuptools' find_packages installs it)."""
