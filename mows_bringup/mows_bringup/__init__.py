"""Starts the MOWS node graph: ``mows-graph`` here, ``launch/mows.launch.py`` on a full install."""
