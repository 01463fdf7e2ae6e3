"""Driver in the loop: a person drives the follower behind the trust-aware AV from a browser.

Layers (each imports only those before it): :mod:`.follower` (the follower plant's pure
rules), :mod:`.trust_rating` (questionnaire scoring and the ratings-vs-models comparison),
:mod:`.sessions` (participants, counterbalanced conditions, resume, withdrawal) are pure
core; :mod:`.follower_node` is the follower plant node; :mod:`.server` serves the page;
:mod:`.drive_run` runs one drive through the graph in wall mode; :mod:`.bag_data` reads a
drive's bag back.
"""
