"""Trust-aware nonlinear MPC of the automated vehicle: the NMPC, the plan estimators, the
planner, ego-plant and stand-in nodes.

The application that lived here (``cli``, ``graph``, ``study``, ``system``, ``drive``) is the
package :mod:`trust_av`; the person-driven follower plant is :mod:`human_driver_sim`'s and
the trust-model fit :mod:`trust_monitor`'s. The old import paths (:data:`MOVED`) still work
for one release and warn with the new one.
"""

# import-rewrite: keep (the old import paths below are on purpose)

from trust_av_common.moved import install

__all__: list[str] = []

MOVED = {
    'trust_av_planner.cli': 'trust_av.cli',
    'trust_av_planner.graph': 'trust_av.graph',
    'trust_av_planner.graph.drive': 'trust_av.drive.graph_run',
    'trust_av_planner.graph.drive_link': 'trust_av.drive.link',
    'trust_av_planner.study': 'trust_av.study',
    'trust_av_planner.study.drive_session': 'trust_av.drive.run_session',
    'trust_av_planner.system': 'trust_av.system',
    'trust_av_planner.drive': 'trust_av.drive',
    'trust_av_planner.drive.follower': 'human_driver_sim.follower_plant',
    'trust_av_planner.drive.follower_node': 'human_driver_sim.follower_plant_node',
    'trust_av_planner.drive.trust_fit': 'trust_monitor.trust_fit',
}
"""Old module or package -> its new place (a package's entry covers its submodules)."""

install(MOVED)
