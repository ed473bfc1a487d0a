"""Latency in the node graph in the driver's tracking mode: from the last sample of each of its
ring-downs to the published fit (``mows-latency --tracking``, :mod:`mows.bench.latency`)."""

from mows.bench import latency


def run(cycles: int = 8, repeats: int = 5) -> dict:
    """Figures over ``cycles`` × ``repeats`` tracking ring-downs."""
    return latency.run(cycles, repeats, tracking=True)
