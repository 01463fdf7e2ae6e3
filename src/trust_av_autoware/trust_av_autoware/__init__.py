"""Adapters between an Autoware stack and the trust-aware planner: its AV and perceived objects
in, its control command out (docs/operations/real-vehicle.md)."""

__all__: list[str] = []
