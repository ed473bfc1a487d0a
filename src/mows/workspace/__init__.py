"""Workspace maps: a Maxwell-consistent model of B and G over a robot's workspace, fitted to
sweeps (or Hall-probe points) measured at many poses.

The field of a source-free region as the gradient of a scalar potential in regular solid
harmonics (``harmonics``); what one sweep or Hall point at one pose says about it, a linear
readout of B, G and H there (``observations``); the weighted least-squares fit, its predictions
with σ and the degree chosen by cross-validation over sweeps (``fit``); force and torque on a
magnetic tool (``tool``); the arm's pose error carried by the fit, errors in variables
(``poses``); the next best pose, D- or I-optimal (``design``); the arm that carries the
probe as CRTK names it (``measured_cp``, ``move_cp``), simulated, and the checks a sweep's
pose must pass (``arm``); sweeps and Hall points simulated in a known field, decomposed by the
sweep's own code (``simulated``); a map as the mapper makes it, live or from a recording: the
pose plan, the checks on the arm's reports through a sweep, the fit (``mapping``).

May import: ``mows.sweep`` (a sweep's decomposition), ``mows.physics``, ``mows.records``; the
simulated measurements also ``mows.sim`` (the field they are taken in), the fit never.
"""
