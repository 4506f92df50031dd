"""A hostile man-in-the-middle UDP proxy between ``gcs fly`` and ``sitl`` (the hostile-link suite).

Topology (all on loopback)::

    sitl --udp 127.0.0.1:V  --->  [V: vehicle socket]  MitmProxy  [ground socket]
                                          ^                              |
                                          |                              v
                                          |                 gcs fly --connect udpin:127.0.0.1:G
                                          +---- [alt socket: a second source address, for injections]

Every datagram is forwarded through a list of seeded :class:`Fault` objects (one
``random.Random(seed)`` for the whole proxy), which may drop, mutate, delay, duplicate, split,
reorder it or inject more datagrams next to it.  Before any fault touches it, every datagram is
decoded by the :class:`Monitor` (the wire checker: the ground station's commands checked, the
vehicle's telemetry taken as the truth).

Modules: :mod:`.wire` (directions, framing, decoding), :mod:`.monitor` (the wire checker),
:mod:`.faults` (byte and timing faults), :mod:`.forgery` (valid frames with hostile contents),
:mod:`.proxy` (:class:`MitmProxy`), :mod:`.clobberer` (:class:`StreamClobberer`, a second client).

Nothing here imports ``gcs`` or ``sitl``: only pymavlink and the standard library.
"""

from .clobberer import StreamClobberer
from .faults import (BitFlip, Burst, Delay, Drop, Duplicate, Fault, FaultStats, GarbageDatagrams, InlineGarbage,
                     LoneMagic, Out, Reorder, Truncate)
from .forgery import ForgedSigned, HostileFields, OtherSystem, mutate_fields
from .monitor import Monitor, Violation
from .proxy import MitmProxy
from .wire import DOWN, MAX_BODY_RATE, UP, decode_frames, mavlink, new_parser, split_frames

__all__ = ["MitmProxy", "Monitor", "Violation", "StreamClobberer", "Fault", "FaultStats", "Out", "DOWN", "UP",
           "MAX_BODY_RATE", "mavlink", "split_frames", "decode_frames", "new_parser",
           "GarbageDatagrams", "LoneMagic", "InlineGarbage", "Truncate", "BitFlip", "Duplicate", "Reorder", "Delay",
           "Burst", "Drop", "HostileFields", "OtherSystem", "ForgedSigned", "mutate_fields"]
