"""Study conditions in which trust moves: moments at which the AV is inexplicable.

With the paper's parameters the AV's plan almost always matches the plan the person expects
(E is small, P >= P_thre), so every trust model sits near its ceiling and ratings cannot tell
the models apart (docs/concepts/trust-models.md, "Drives in which trust moves"). A
*perturbation* is a documented, scheduled departure of the AV's command from what its NMPC
planned, applied by the planner core (:class:`~trust_av_planner.planner.AvPlanner`) after the
solve, so the in-process loop and the node graph apply it identically and the monitor scores
the plan the AV actually commands.

Event kinds (times relative to the first planning step of the run, s):

- ``brake``: late hard braking. While ``start_s <= t < start_s + duration_s`` every plan
  element that falls inside the window is capped at ``level_mps2`` (then clipped to the
  planner's ``accel_min_mps2``); the NMPC did not ask for it and the plan gave no warning.
- ``hesitate``: the AV hesitates, the same cap at a mild deceleration for longer, whatever
  the NMPC wanted (also when the traffic ahead pulls away).
- ``headway``: an unannounced headway change. From ``start_s`` on the NMPC plans from a gap
  ``headway_s * v_AV`` shorter than the real one, so it opens the gap to the CTH headway
  ``time_headway_s + headway_s`` (> 0 only: the real gap is always larger than planned).

**A condition never makes the AV hit the car ahead.** A brake or hesitation leaves the AV
far behind; its NMPC (3 s preview) then closes the gap at full acceleration and could be too
fast to stop when the lead stopped beyond the preview (``rough_random`` on US06 collided at
about 40 s on 7 of seeds 0-299, then with 2-4 s between events). So while a condition is
active every command is also capped
by :func:`stopping_cap_mps2`: after the step the AV can still brake at its own limit to a
stop at least its standstill gap d_s (``standstill_gap_m``) behind where the lead stops,
the lead braking no harder than the AV can from the speed the NMPC's preview gives it at
the next step. A step at the limit keeps that true (the invariant in the function's
docstring), so from a state the cap allowed, braking at the limit is always enough. In
rough drives the cap changes about 8 % of the commands (the AV closing fast on a slower
lead). A run without a condition (``none``:
the paper's runs, Tables II-IV) is not capped at all.

The library (:data:`LIBRARY`) names the conditions a study selects with the planner
parameter ``perturbation`` (per condition in ``config/drive.yaml``:
``condition_perturbations``); ``*_random`` conditions draw their times from
``perturbation_seed`` (numpy's PCG64), so a drive is reproducible from its recorded seed.
Pure: no ROS, no wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trust_av_common.params import param

__all__ = ['CONDITION_PARAM', 'LIBRARY', 'SEED_PARAM', 'Perturbation', 'schedule',
           'stopping_cap_mps2']

BRAKE, HESITATE, HEADWAY = 'brake', 'hesitate', 'headway'
FIXED_CONDITION = 'the study condition of a run is fixed'
"""Why the planner's ``perturbation`` parameters are read-only."""


@dataclass(frozen=True)
class Event:
    """One departure of the AV from its planned command.

    Attributes:
        kind: ``brake``, ``hesitate`` or ``headway``.
        start_s: when it begins, s after the run's first step.
        duration_s: how long a cap lasts, s (``headway``: ignored, it persists).
        level_mps2: the cap on the commanded acceleration, m/s^2 (``brake``, ``hesitate``).
        headway_s: added CTH headway, s (``headway``).
    """

    kind: str
    start_s: float
    duration_s: float = 0.0
    level_mps2: float = 0.0
    headway_s: float = 0.0


def late_brake(start_s: float) -> Event:
    """Hard braking (-3 m/s^2, the AV's Table I limit) for 1 s."""
    return Event(BRAKE, start_s, 1.0, -3.0)


def hesitation(start_s: float) -> Event:
    """A 2 s hesitation at -1.5 m/s^2."""
    return Event(HESITATE, start_s, 2.0, -1.5)


def headway_change(start_s: float) -> Event:
    """The AV silently keeps 1 s more headway from ``start_s`` on."""
    return Event(HEADWAY, start_s, headway_s=1.0)


SCHEDULED: dict[str, tuple[Event, ...]] = {
    'none': (),
    'late_brake': tuple(late_brake(t) for t in (20.0, 40.0, 60.0, 80.0, 100.0)),
    'hesitation': tuple(hesitation(t) for t in (15.0, 35.0, 55.0, 75.0, 95.0)),
    'headway_change': (headway_change(40.0),),
    'mixed': (hesitation(15.0), late_brake(40.0), headway_change(65.0), late_brake(95.0)),
}
"""Conditions at fixed moments (within the first 120 s: the study's default drive)."""
RANDOM_WINDOW_S = (10.0, 110.0)
"""``*_random`` conditions place their events in this window, s."""
RANDOM_EVENTS = 5
"""Events per ``*_random`` condition."""
RANDOM_MIN_SPACING_S = 15.0
"""Least time between two random events, s (each recovers before the next)."""
RANDOM_KINDS = {'late_brake_random': (late_brake,), 'hesitation_random': (hesitation,),
                'mixed_random': (late_brake, hesitation)}
ROUGH = 'rough_random'
"""Rough patches: trust falls in them and recovers between them (:func:`rough_patches`)."""
ROUGH_FIRST_S = (8.0, 15.0)
"""``rough_random``: the first patch starts in this interval, s."""
ROUGH_PATCH_S = (20.0, 35.0)
"""Length of a rough patch, s."""
ROUGH_CALM_S = (8.0, 14.0)
"""Calm between two patches, s (the AV is explicable: trust recovers)."""
ROUGH_GAP_S = (1.0, 2.5)
"""Time from the end of one event of a patch to the start of the next, s (dense enough to
inform a fit; the AV that falls far behind in a patch is kept able to stop when it catches
up: :func:`stopping_cap_mps2`)."""
ROUGH_BRAKE_MPS2 = (-3.0, -0.8)
"""Cap of a 1 s brake in a patch, m/s^2 (its depth sets how inexplicable it is)."""
ROUGH_HESITATE_MPS2 = (-1.5, -0.5)
"""Cap of a 2 s hesitation in a patch, m/s^2."""
ROUGH_END_S = 110.0
"""No event of ``rough_random`` starts after this, s (the study's 120 s drive)."""
LIBRARY: tuple[str, ...] = (*SCHEDULED, *RANDOM_KINDS, ROUGH)
"""Every condition name the ``perturbation`` parameter accepts."""
CONDITION_PARAM = param('study condition: when the AV departs from its plan (none: never)',
                        choices=LIBRARY, default='none', reason=FIXED_CONDITION)
"""The planner's ``perturbation`` parameter (a field of its ``PlannerConfig``)."""
SEED_PARAM = param('seed of a *_random perturbation (its event times)', low=0,
                   high=2**32 - 1, default=0, reason=FIXED_CONDITION)
"""The planner's ``perturbation_seed`` parameter."""


def schedule(name: str, seed: int = 0) -> tuple[Event, ...]:
    """The events of condition ``name`` (seeded conditions: drawn from ``seed``).

    Raises:
        ValueError: ``name`` is not in :data:`LIBRARY`.
    """
    if name in SCHEDULED:
        return SCHEDULED[name]
    if name == ROUGH:
        return rough_patches(seed)
    if name not in RANDOM_KINDS:
        raise ValueError(f'perturbation must be one of {list(LIBRARY)}, got {name!r}')
    rng = np.random.Generator(np.random.PCG64(seed))
    low, high = RANDOM_WINDOW_S
    # spaced times: sorted uniform draws in the window shrunk by the spacing, then spread
    slack = high - low - (RANDOM_EVENTS - 1) * RANDOM_MIN_SPACING_S
    times = np.sort(rng.uniform(0.0, slack, RANDOM_EVENTS)) + low \
        + RANDOM_MIN_SPACING_S * np.arange(RANDOM_EVENTS)
    makers = RANDOM_KINDS[name]
    kinds = rng.integers(0, len(makers), RANDOM_EVENTS)
    return tuple(makers[int(k)](round(float(t), 3)) for t, k in zip(times, kinds, strict=True))


def rough_patches(seed: int) -> tuple[Event, ...]:
    """``rough_random``: patches of brakes and hesitations of random depth with calm
    between them, all drawn from ``seed`` (PCG64).

    A patch (:data:`ROUGH_PATCH_S` long) is a run of events, each a 1 s brake capped at a
    level uniform in :data:`ROUGH_BRAKE_MPS2` or a 2 s hesitation capped in
    :data:`ROUGH_HESITATE_MPS2` (even odds), the next one :data:`ROUGH_GAP_S` after its end;
    patches are :data:`ROUGH_CALM_S` apart. Each event is explicable to a different degree,
    so in a patch the performance P = 1 - tanh(E) takes values across (0.5, 1): where a
    model's threshold lies decides which of them lower trust, and how much a fall weighs
    against a gain decides whether trust falls in the patch or only rises more slowly.
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    events = []
    t = float(rng.uniform(*ROUGH_FIRST_S))
    while t < ROUGH_END_S:
        end = min(t + float(rng.uniform(*ROUGH_PATCH_S)), ROUGH_END_S)
        while t < end:
            if rng.uniform() < 0.5:
                event = Event(BRAKE, round(t, 3), 1.0,
                              round(float(rng.uniform(*ROUGH_BRAKE_MPS2)), 3))
            else:
                event = Event(HESITATE, round(t, 3), 2.0,
                              round(float(rng.uniform(*ROUGH_HESITATE_MPS2)), 3))
            events.append(event)
            t += event.duration_s + float(rng.uniform(*ROUGH_GAP_S))
        t += float(rng.uniform(*ROUGH_CALM_S))
    return tuple(events)


class Perturbation:
    """A condition's events applied to the planner's steps.

    Args:
        name: a :data:`LIBRARY` name.
        seed: the seed of a ``*_random`` condition.
        accel_min_mps2: the planner's lower acceleration bound (caps never go below it).
    """

    def __init__(self, name: str, seed: int, accel_min_mps2: float) -> None:
        self.name = name
        self.events = schedule(name, seed)
        self.accel_min_mps2 = accel_min_mps2

    @property
    def active(self) -> bool:
        """Whether the condition has any event."""
        return bool(self.events)

    def headway_s(self, t_s: float) -> float:
        """Headway added at ``t_s`` (s after the first step), s."""
        return sum(e.headway_s for e in self.events if e.kind == HEADWAY and t_s >= e.start_s)

    def apply(self, plan_mps2: np.ndarray, t_s: float, step_s: float) -> np.ndarray:
        """The commanded plan at ``t_s``: ``plan_mps2`` (on a grid of ``step_s``) with every
        cap in force applied to the elements inside its window (a new array)."""
        out = np.array(plan_mps2, dtype=float)
        times = t_s + step_s * np.arange(len(out))
        for e in self.events:
            end = e.start_s + e.duration_s
            if e.kind == HEADWAY or not e.start_s <= t_s < end:
                continue
            inside = times < end
            out[inside] = np.minimum(out[inside], max(e.level_mps2, self.accel_min_mps2))
        return out


ROOM_TOLERANCE_M = 1e-9
"""Rounding allowed at the edge of :func:`stopping_cap_mps2`'s bound, m."""


def stopping_distance_m(speed_mps: float, brake_mps2: float, dt_s: float) -> float:
    """How far the loop's explicit Euler steps (``x += v dt``, then ``v -= b dt``, never below
    0) carry a vehicle braking at ``brake_mps2`` from ``speed_mps`` until it stops, m:
    ``S(v) = dt sum_k max(v - k b dt, 0)`` (so ``S(v) = v dt + S(v - b dt)``)."""
    step = brake_mps2 * dt_s
    n = math.floor(max(speed_mps, 0.0) / step)
    return dt_s * ((n + 1) * max(speed_mps, 0.0) - step * n * (n + 1) / 2.0)


def stopping_cap_mps2(speed_mps: float, gap_m: float, lead_speed_mps: float,
                      lead_next_mps: float, dt_s: float, brake_mps2: float,
                      margin_m: float) -> float:
    """The largest acceleration for the next step after which the AV can still stop at
    least ``margin_m`` behind the lead's stop, both braking at ``brake_mps2`` (> 0) from
    the next step on (the lead's speed then: ``lead_next_mps``, from the preview);
    ``-inf`` when none can.

    The loop's explicit Euler step makes the next gap ``gap + (v_L - v) dt`` whatever the
    command ``a`` is; ``a`` sets the next speed ``v1 = v + a dt``, and the cap is the
    largest ``v1`` with ``S(v1) <= gap + (v_L - v) dt + S(u) - margin``
    (:func:`stopping_distance_m`, ``u`` the lead's next speed). Invariant: when a step met
    this, a step at ``-b`` meets it again (``S(v1) = v1 dt + S(v1 - b dt)``, and a lead that
    brakes no harder than ``b`` runs at least ``S(u) - u dt`` after its next step), and the
    gap stays above ``min(gap now, margin)``; so from a capped state braking at the limit is
    always enough.
    """
    b, dt = brake_mps2, dt_s
    room = (gap_m + (lead_speed_mps - speed_mps) * dt
            + stopping_distance_m(lead_next_mps, b, dt) - margin_m)
    if room < -ROOM_TOLERANCE_M:   # a state the cap made lies on its edge, up to rounding
        return -math.inf
    room = max(room, 0.0)
    # S is piecewise linear, S(n b dt) = b dt^2 n (n + 1) / 2: the segment holding `room`
    n = math.floor((-1.0 + math.sqrt(1.0 + 8.0 * room / (b * dt * dt))) / 2.0)
    next_speed = (room / dt + b * dt * n * (n + 1) / 2.0) / (n + 1)
    return (next_speed - speed_mps) / dt
