"""The physics of the magneto-oscillatory sensor, from first principles (docs/physics.md).

The probe's constants (``probe``), field sources (``field``: the closed-form ``sources`` and
current ``loops``, with their YAML form), where the probe sits
(``pose``), the full potential U(θ) of the magnet on its lever (``potential``; the balance of a swing in
it, ``harmonic_balance``), the published
frequency model and its inverses (``frequency``, Eqs. 1, 4–8, S13–S24), the amplitude a decaying
ring-down's frequency belongs to (``ringdown_average``), the magnetometer signal (``signal``,
``fluxgate``), the excitation coils (``coils``) and what probes sharing a scene do to each other
(``coupling``); ``schema`` is the one loader of our YAML files (probe files, scenarios, the
bench's files, the estimator's ``probes``) and checks their mappings and arguments into arrays.

May import: ``mows.records``, numpy, scipy, numba, pyyaml. Nothing here simulates, does I/O
beyond reading YAML, or fits data.
"""
