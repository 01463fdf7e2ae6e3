"""The trust-av application over the four domain packages: the ``trust-av`` command line
(:mod:`trust_av.cli`), the node graph's orchestrator and recorder (:mod:`trust_av.graph`),
the in-process closed loop and the run configuration (:mod:`trust_av.system`), the studies
(:mod:`trust_av.study`), the driver-in-the-loop drive (:mod:`trust_av.drive`) and the plug-in
contract (:mod:`trust_av.contract`).
"""

__all__: list[str] = []
