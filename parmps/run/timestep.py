"""The step length: the case's fixed dt, or the largest the steppers' stability limits allow.

A stepper reports its limits as :class:`Limit` (a name, seconds, and the reason
in words). Adaptive steps take the smallest limit and ``time.dt_max``; a fixed
step that breaks a limit stops the run with the reason rather than going on to
NaN. A limit that makes dt zero, vanishingly small or non-finite at the first
step is bad input: the parameters behind it (named in the reason) can give no
run; later it is a run that went unstable.
"""

import math
from dataclasses import dataclass

from parmps.errors import CaseError, RunFailure

# Below this a step is no step: 1/dt^2 in the PPE overflows long before.
SMALLEST_STEP = 1e-100


@dataclass(frozen=True)
class Limit:
    name: str        # e.g. "Courant", "viscous"
    seconds: float
    reason: str      # what sets it, naming the case keys


def choose_dt(settings, limits, step):
    """dt for ``step`` from the case's ``[time]`` settings and the steppers' limits."""
    fixed = settings["fixed_dt"]
    if fixed > 0:
        for limit in limits:
            if fixed > limit.seconds:
                raise RunFailure(
                    f"step {step}: the fixed time.fixed_dt = {fixed:g} s breaks the "
                    f"{limit.name} limit: {limit.reason}; lower time.fixed_dt or set it to 0 "
                    f"for adaptive steps")
        return fixed
    dt = settings["dt_max"]
    binding = None
    for limit in limits:
        if limit.seconds < dt:
            dt, binding = limit.seconds, limit
    if not (math.isfinite(dt) and dt > SMALLEST_STEP):
        cause = binding.reason if binding is not None else "time.dt_max"
        # At the first step the input alone sets the limits; later the flow does.
        error = CaseError if step <= 1 else RunFailure
        raise error(f"step {step}: the time step would be {dt:g} s ({cause}): no run can "
                    f"advance with it")
    return dt
