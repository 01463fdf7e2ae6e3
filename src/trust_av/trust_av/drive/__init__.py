"""Driver in the loop, every application part of it in one place: a person drives the
follower behind the trust-aware AV from a browser page.

:mod:`.trust_rating` (questionnaire scoring, ratings vs trust models), :mod:`.sessions`
(participants, counterbalancing, resume, the participant's lock), :mod:`.withdrawal`
(deleting what trust-av wrote for a participant), :mod:`.study` (settings, summaries),
:mod:`.bag_data` (a drive's bag read back), :mod:`.server` (the page and its WebSocket:
who may connect and drive), :mod:`.gate` (what the driving page may send, when),
:mod:`.synthetic` (a synthetic participant for tests and benchmarks); the page itself is in
``web/``. One drive through the graph is :mod:`.graph_run` (its messages to and from the
page: :mod:`.link`); a participant's session, :mod:`.run_session`; the command
``trust-av drive``, :mod:`.command`. The participant's car (the person-driven follower plant
and its node) is :mod:`human_driver_sim.follower_plant`; fitting trust models to the
ratings, :mod:`trust_monitor.trust_fit`.
"""

__all__: list[str] = []

