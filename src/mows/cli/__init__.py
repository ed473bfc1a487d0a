"""The ``mows`` command: ``mows sim``, ``mows fit``, ``mows lab …``, ``mows bench`` (``main``).

The top layer: may import every other part of ``mows``; nothing else of ``mows`` imports it.
"""
