"""Stepwise model selection (``stepwise``): physics preferred to generic terms, and the history
of the error as effects are added.

May import: ``mows.lab.diagnosis``, ``mows.lab.model``, ``mows.lab.data``, ``mows.lab.progress``
and the core below the lab.
"""
