"""MOWS: physics, simulation, ring-down fitting, decomposition and the model lab for the
magneto-oscillatory wireless sensor of Fischer, Jeong & Qiu (equation numbers refer to that
paper: (1)-(12) main text, (S1)-(S24) supplement). Pure Python; never imports rclpy."""

__version__ = "0.1.0"
