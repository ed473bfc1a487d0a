"""Rotation sweeps: (θ0, Δf) points of many orientations decomposed into in-plane field and
gradient (``decompose``).

May import: ``mows.estimate``, ``mows.physics``, ``mows.records``.
"""
