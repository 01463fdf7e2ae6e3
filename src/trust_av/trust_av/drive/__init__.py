"""Driver in the loop, pure part: a person drives the follower behind the trust-aware AV
from a browser page.

:mod:`.follower` (the participant's car and its reaction to a lost participant),
:mod:`.trust_rating` (questionnaire scoring, ratings vs trust models), :mod:`.sessions`
(participants, counterbalancing, resume, withdrawal), :mod:`.study` (settings, summaries),
:mod:`.bag_data` (a drive's bag read back), :mod:`.server` (the page and its WebSocket:
who may connect and drive), :mod:`.gate` (what the driving page may send, when),
:mod:`.synthetic` (a synthetic participant for tests and benchmarks); the page itself is in
``web/``. The follower plant node is :mod:`.follower_node`; one drive through the graph is
:mod:`trust_av.drive.graph_run`; a session, :mod:`trust_av.drive.run_session`.
"""

__all__: list[str] = []

