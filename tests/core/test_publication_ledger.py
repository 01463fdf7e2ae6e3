"""The wall-mode recording's loss count (``graph/publication_ledger.py``): pure, from
publication sequence numbers and the nodes' published counts. Same on every CPU."""

from __future__ import annotations

import pytest

from trust_av.graph.publication_ledger import (
    Lost,
    PublicationLedger,
    RecordingLossError,
    check_lossless,
)


def ledger_of(topic: str, node: str, numbers: list[int]) -> PublicationLedger:
    ledger = PublicationLedger()
    for number in numbers:
        ledger.received(topic, node, number)
    return ledger


def test_nothing_lost_when_every_number_up_to_the_published_count_came() -> None:
    ledger = ledger_of('/ego/odom', 'ego_plant', [3, 4, 5, 6])   # 1-2 before the match
    assert ledger.lost({('/ego/odom', 'ego_plant'): 6}) == []
    check_lossless(ledger, ledger.lost({('/ego/odom', 'ego_plant'): 6}))


def test_a_hole_in_the_middle_and_an_unreceived_tail_are_counted() -> None:
    ledger = ledger_of('/ego/odom', 'ego_plant', [1, 2, 5, 6, 7])
    assert ledger.lost({('/ego/odom', 'ego_plant'): 9}) == [
        Lost('/ego/odom', 'ego_plant', 4, 3, 9)]


def test_a_publisher_that_started_after_the_recording_is_counted_from_one() -> None:
    key = ('/preceding_vehicle/odom', 'preceding_traffic')
    ledger = ledger_of(*key, [4, 5])
    assert ledger.lost({key: 5}) == []
    assert ledger.lost({key: 5}, from_first={key}) == [Lost(*key, 3, 1, 3)]


def test_publishers_of_one_topic_are_counted_apart() -> None:
    ledger = ledger_of('/tf', 'ego_plant', [1, 2, 3])
    ledger.received('/tf', 'human_driver', 1)
    ledger.received('/tf', 'human_driver', 3)
    assert ledger.lost({('/tf', 'ego_plant'): 3, ('/tf', 'human_driver'): 3}) == [
        Lost('/tf', 'human_driver', 1, 2, 2)]


def test_a_publisher_never_heard_loses_all_it_published() -> None:
    ledger = PublicationLedger()
    assert ledger.lost({('/human/plan', 'human_driver'): 4, ('/quiet', 'node'): 0}) == [
        Lost('/human/plan', 'human_driver', 4, 1, 4)]


def test_the_loss_is_one_line_naming_each_publisher_and_the_count() -> None:
    ledger = ledger_of('/ego/odom', 'ego_plant', [1, 2, 5])
    ledger.received('/trust_monitor/trust', 'trust_monitor', 1)
    with pytest.raises(RecordingLossError) as lost:
        check_lossless(ledger, ledger.lost({('/ego/odom', 'ego_plant'): 5,
                                            ('/trust_monitor/trust', 'trust_monitor'): 2}))
    line = str(lost.value)
    assert '\n' not in line
    assert line.startswith('the recording lost 3 of 7 messages, /ego/odom from ego_plant: 2 '
                           '(publications 3-4); /trust_monitor/trust from trust_monitor: 1 '
                           '(publications 2): ')
    assert [loss.count for loss in lost.value.losses] == [2, 1]


def test_a_best_effort_publisher_s_last_message_alone_is_the_stop_edge() -> None:
    """The one sample a node may publish while it is being stopped is not a loss on a
    best-effort topic; two are, and a hole before it still is."""
    key = ('/ego/odom', 'ego_plant')
    assert ledger_of(*key, [1, 2, 3]).lost({key: 4}, stop_edge={key}) == []
    assert ledger_of(*key, [1, 2, 3]).lost({key: 4}) == [Lost(*key, 1, 4, 4)]
    assert ledger_of(*key, [1, 2]).lost({key: 4}, stop_edge={key}) == [Lost(*key, 2, 3, 4)]
    assert ledger_of(*key, [1, 3]).lost({key: 4}, stop_edge={key}) == [Lost(*key, 1, 2, 2)]
