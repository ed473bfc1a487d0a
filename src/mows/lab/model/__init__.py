"""The frequency model and what can be added to it.

``configuration`` (the per-row :class:`Configuration`), ``factors`` (its frequency through
the full potential), ``effects`` (the :class:`Effect` and :class:`Parameter` types), ``plugins`` (the
:func:`effect` decorator, :func:`load_plugins`), ``catalog`` (the built-in effects),
``least_squares`` (one model's weighted least-squares problem on a table, :class:`FitResult`)
and ``frequency_model`` (:class:`FrequencyModel`: Eq. 6 + effects, ``+`` composes, and its fit).

May import: ``mows.lab.data``, ``mows.lab.progress`` and the core below the lab.
"""
