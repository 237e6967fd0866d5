"""ROS 2 nodes: thin shells over the core. The only package that imports rclpy and messages.

- ``recorder``: records the bag contract's topics as raw bytes to a crash-safe MCAP bag.
- ``replay``: plays a bag at the recorded IPO pace and publishes the predictor's reference.
- ``predictor``: guarded feed-forward tau_u from a model artifact, per reference sample.

Each module holds an importable node class and ``main(args=None)`` (the console scripts
``recorder``, ``replay`` and ``predictor``). Nothing is imported here, so that starting one node
does not load the others' dependencies.
"""

from __future__ import annotations

__all__ = ['msg_conversions', 'params', 'predictor', 'qos', 'recorder', 'replay', 'runtime']
