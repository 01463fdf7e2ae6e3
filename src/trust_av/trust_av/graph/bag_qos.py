"""A topic's offered QoS as a bag records it (``offered_qos_profiles``), from the rclpy
profile its publisher uses."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos

from trust_av.graph.bag_writer import qos_profile

__all__ = ['offered_profiles', 'offered_qos']


def offered_qos(profile: QoSProfile) -> Qos:
    """The bag's record of a topic's offered QoS (keep-last, the profile's depth and
    deadline)."""
    return qos_profile(reliable=profile.reliability == ReliabilityPolicy.RELIABLE,
                       transient_local=profile.durability == DurabilityPolicy.TRANSIENT_LOCAL,
                       depth=profile.depth, deadline_ns=int(profile.deadline.nanoseconds))


def offered_profiles(profile: QoSProfile, publishers: int) -> list[Qos]:
    """A topic's ``offered_qos_profiles`` as ``ros2 bag record`` writes them: one profile
    per publisher it found (rosbag2_transport ``recorder.cpp`` collects the offered QoS of
    every publisher of the topic), here ``publishers`` publishers of ``profile``."""
    return [offered_qos(profile)] * max(1, publishers)
