"""trust_av.study (a regular package, so that setuptools' find_packages installs it)."""

__all__: list[str] = []

