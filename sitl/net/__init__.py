"""What both simulated vehicles are served over: transports, link emulation and the one server loop.

``transport`` (the interface) with ``udp``, ``tcp`` and ``pty``; ``radio`` (baud, loss, latency);
``endpoint`` and ``links`` (MAVLink framing and one link per peer, the copter's); ``loop`` (thread,
select and the real-time and lockstep run loops of every server).
"""
