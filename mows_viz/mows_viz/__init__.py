"""The MOWS graph live in Foxglove: the ``mows_viz`` node (``node``: subscriptions fed to the
core's :class:`mows.viz.view.View`, its channels served by foxglove-sdk's WebSocket server;
``parameters``: its table) and the layout ``config/mows.foxglove.json``.

May import: ``mows_ros``, ``mows`` (``mows.viz``), ``mows_msgs``, rclpy and foxglove-sdk.
"""
