"""What Foxglove shows of a running graph or of its recording (docs/visualisation.md).

The graph's messages go in, Foxglove's channels come out: the probe mount's frames, each
probe's field and gradient as arrows with value ± σ in a 3D scene, the raw fluxgate stream,
each ring-down beside its fitted model and residual, the sweep's Δf against θ0 beside its
decomposition, the model lab's error history, the excitation and /diagnostics. The modules, in
the order they build on each other:

- ``curves``: the plotted curves from a result's numbers: a ring-down's model (Eqs. S2, S11)
  and residual, a sweep's harmonic series (Eq. 12), decimation of long series.
- ``scene``: arrows of the in-plane field and of the gradient's principal directions, their
  lengths and labels (value ± σ).
- ``workspace_scene``: a workspace map's B on a grid through its ball, |B| ± σ, and its poses.
- ``mount``: a URDF's frames at the stage's angle (the probe mount's TF).
- ``view``: **View**, an I/O-free translator: the graph's messages (rclpy's or a bag's, read by
  attribute) in, each channel's messages out.
- ``channels``: the channels' topics, schemas and bytes (Foxglove's protobuf schemas from
  ``foxglove-sdk``, JSON with a JSON schema for the plots).
- ``live``: the live server's channels, each one's last message re-sent to a client that
  subscribes later.
- ``recording``: a recorded bag's derived channels written into an MCAP file (``mcap``).
- ``figures``: each panel's content drawn as a PNG (matplotlib), from the same channel content.

May import: ``mows.workspace`` (a map's model), ``mows.estimate``, ``mows.device`` (the bag reader), ``mows.physics``,
``mows.records``, and ``foxglove-sdk``, ``mcap`` and ``matplotlib``; never ``rclpy``.
"""
