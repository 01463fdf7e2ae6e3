"""trust_av.system (a regular package, so that setuptools' find_packages installs it)."""

__all__: list[str] = []

