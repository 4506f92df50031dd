"""The paper's indoor 4-DOF rig: plant (``dynamics``), ``sensors``, onboard ``firmware``, serial ``link``, ``server``.

The wire format is :mod:`quadrotor.rig_protocol`, shared with the ground station.
"""
