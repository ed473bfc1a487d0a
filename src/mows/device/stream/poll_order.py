"""The order in which a session takes what two polls of its device brought.

A command sent by another thread (the driver's executor starting a cycle) while the streaming
thread is between a poll and taking what it read reaches the device after those samples: they
cannot hold its answer, which the next poll brings. Taken in arrival order, they would count
against the answer's deadline (device time): after a host stall one poll reads more than that,
and the cycle failed for an answer the device had given at once.
"""

from mows.device.interface import CommandResult
from mows.records.samples import SampleBlock


def answers_first(read: list, since: list) -> list:
    """What one poll ``read`` and the next brought (``since``), with the command results of the
    next ahead of the samples of the first."""
    answers = [item for item in since if isinstance(item, CommandResult)]
    first = next((k for k, item in enumerate(read) if isinstance(item, SampleBlock)), len(read))
    return [*read[:first], *answers, *read[first:], *(item for item in since if not isinstance(item, CommandResult))]
