"""Benchmarks behind ``mows bench``: each module has ``run(...) -> dict`` of printed figures.

Figures only: nothing here asserts a timing (tests never depend on the machine's speed).
"""
