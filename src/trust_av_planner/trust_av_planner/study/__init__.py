"""trust_av_planner.study (a regular package, so that setuptools' find_packages installs it)."""
