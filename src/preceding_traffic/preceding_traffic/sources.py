"""Where a preceding-traffic speed trace comes from: a shipped trace, a CSV or a rosbag2 bag.

:func:`load_trace` is the one entry point the nodes and the CLI use; it dispatches to the CSV
reader (:mod:`preceding_traffic.traces`) or the bag reader (:mod:`preceding_traffic.bags`),
which both validate and resample onto the control grid with the same rules.
"""

from __future__ import annotations

from pathlib import Path

from preceding_traffic.traces import (
    SHIPPED_TRACES,
    TRAINING_TRACES,
    SpeedTrace,
    TraceConfig,
    check_accelerations,
    read_samples,
    resample,
    trace_path,
)

__all__ = ['load_trace']


def is_bag(path: Path) -> bool:
    """A rosbag2 bag: a directory with ``metadata.yaml``, or an ``.mcap``/``.db3`` file."""
    return (path.is_dir() and (path / 'metadata.yaml').exists()) or path.suffix in {'.mcap',
                                                                                   '.db3'}


def load_trace(name_or_path: str, dt_s: float, config: TraceConfig) -> SpeedTrace:
    """Load a shipped trace by name, a CSV, or a bag's speed topic onto the control grid.

    Args:
        name_or_path: a name of :data:`SHIPPED_TRACES`, a ``time_s,speed_mps`` CSV, or a
            rosbag2 bag (read with ``config.bag_topic`` and ``config.bag_message_type``).
        dt_s: control step, s.
        config: validation settings.

    Raises:
        PrecedingTrafficError: the trace or bag breaks a rule of
            :func:`~preceding_traffic.traces.check_sample`, or speeds up or brakes harder
            than a road vehicle (:func:`~preceding_traffic.traces.check_accelerations`).
    """
    path = trace_path(name_or_path)
    if is_bag(path):
        from preceding_traffic.bags import load_bag_trace  # rosbags only for a bag
        return load_bag_trace(path, config.bag_topic, config.bag_message_type, dt_s, config)
    times, speeds = read_samples(path, config)
    check_accelerations(str(path), times, speeds, config)
    shipped = name_or_path.lower() in SHIPPED_TRACES + TRAINING_TRACES
    name = name_or_path.lower() if shipped else path.stem
    return SpeedTrace(name=name, dt_s=dt_s, speeds_mps=resample(times, speeds, dt_s, str(path)),
                      t0_s=float(times[0]), source=str(path))
