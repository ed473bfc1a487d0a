"""What the mapper publishes when a sweep ends, and how it says a cycle failed.

:func:`publication` turns the runner's last step (:class:`mows.sweep.events.SweepStep`) into
the messages to make, in the order they go out: each probe's decomposition for ``/mows/sweep``,
in its probe's own frame when the ``probes`` setting names the probes, with the field map of
them all at their places; and the sweep the model lab reads when a reference is given and the
probes are not named (the node's own probe: the lab reads one probe's sweep). The mapper node
builds each message and publishes it; nothing here does I/O.
"""

from __future__ import annotations

import dataclasses

from mows.estimate.probe_set import ProbeEntry
from mows.sweep.events import CycleAnswer, SweepMap, SweepSettings, SweepStep


@dataclasses.dataclass(frozen=True)
class Publication:
    """The messages of a finished sweep: ``sweeps`` for ``/mows/sweep``; each decomposition,
    the action result's too, in its probe's own frame when ``per_probe``; the field map of
    ``field_map``'s probes (in the order of ``sweeps``) when there are any; ``lab``, the sweep
    the model lab reads, or None."""

    sweeps: tuple[SweepMap, ...] = ()
    per_probe: bool = False
    field_map: tuple[ProbeEntry, ...] = ()
    lab: SweepMap | None = None

    def summary(self, report: str) -> str:
        """The log line of what went out, with the runner's ``report`` of the decomposition."""
        if self.per_probe:
            return f"sweep of {len(self.sweeps)} probes: {report}"
        return f"sweep {self.sweeps[0].sweep_id}: {report}" if self.sweeps else report


def publication(step: SweepStep, settings: SweepSettings, reference: str) -> Publication:
    """What to publish for the runner's ``step`` at a sweep's end, with the sweep's ``settings``
    (its probes, whether they are named) and the lab's ``reference`` ('' for none) as the
    mapper has them."""
    named, maps = settings.named, step.publish
    return Publication(
        maps,
        per_probe=named,
        field_map=settings.probes if named and maps else (),
        lab=maps[0] if maps and reference and not named else None,
    )


def cycle_failed(answer: CycleAnswer) -> CycleAnswer:
    """The driver's ``answer`` to a cycle the sweep asked for: a problem is that cycle's failure
    ("cycle failed: …"); an answer without one is as it came."""
    return dataclasses.replace(answer, problem=f"cycle failed: {answer.problem}") if answer.problem else answer
