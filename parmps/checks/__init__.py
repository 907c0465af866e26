"""Run-time checks that count, every step, what must not happen and record the count.

A check is an observer (:class:`parmps.run.observers.Observer`) chosen by a
``[[check]]`` table of the case; unlike a guard (:mod:`parmps.run.guards`) it
does not stop the run: the count is the result, in ``/checks/<name>`` of
result.h5. ``CHECKS`` is the one place a check is registered, by the name the
case gives as ``kind``.
"""

from parmps import registry

CHECKS = {
    "body_crossing": "parmps.checks.crossing:BodyCrossing",
    "wall_crossing": "parmps.checks.walls:WallCrossing",
}


def check_observers(case, result, model, interval, end_time):
    """One observer per ``[[check]]`` of the case, in the case's order."""
    observers = []
    for spec in case["check"]:
        kind = registry.load(CHECKS, spec["kind"])
        observers.append(kind(spec, case, result, model, interval, end_time))
    return observers
