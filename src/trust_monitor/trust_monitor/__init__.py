"""Explicability score, performance level and trust dynamics of the human follower.

Ozkan & Ma, eqs. (8)-(11).

The shared floor that lived in ``trust_monitor.common`` and ``trust_monitor.ros`` is the
package :mod:`trust_av_common`, and the trust modules have one name per concept; the old
import paths (:data:`MOVED`) still work for one release and warn with the new one.
"""

# import-rewrite: keep (the old import paths below are on purpose)

from trust_av_common.moved import install

__all__: list[str] = []

MOVED = {
    'trust_monitor.common': 'trust_av_common',
    'trust_monitor.common.contract': 'trust_av.contract',
    'trust_monitor.ros': 'trust_av_common.ros',
    'trust_monitor.trust_model': 'trust_monitor.paper_trust',
    'trust_monitor.trust_models': 'trust_monitor.shipped_models',
    'trust_monitor.trust_interface': 'trust_monitor.model_interface',
    'trust_monitor.trust_bound': 'trust_monitor.final_trust_bound',
}
"""Old module or package -> its new place (a package's entry covers its submodules)."""

install(MOVED)
