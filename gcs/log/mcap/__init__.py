"""The MCAP format layer: a crash-tolerant chunked writer and a robust reader of truncated files.

Nothing here knows what a flight is: messages are bytes on topics, each topic a channel with
the schema its writer's ``schema_of`` callback names.

* :mod:`~gcs.log.mcap.writer` — :class:`McapWriter` (chunked, compressed, flushed at least
  every ``flush_interval_s``, finished on close), :func:`check_writable`, :func:`best_compression`;
* :mod:`~gcs.log.mcap.fast` — :class:`~gcs.log.mcap.fast.FastWriter`, mcap's writer with a
  faster message path (same bytes);
* :mod:`~gcs.log.mcap.reader` — :func:`read_log` (any file, truncated or damaged ones included:
  everything before the first broken record), :func:`read_attachment`;
* :mod:`~gcs.log.mcap.scan` — what the reader is made of (bounded reads, chunk checks, the
  message collector) and its result types :class:`McapLog`, :class:`ChannelInfo`,
  :class:`AttachmentInfo`.
"""

from gcs.log.mcap.reader import MAGIC, AttachmentInfo, ChannelInfo, McapLog, read_attachment, read_log
from gcs.log.mcap.writer import COMPRESSIONS, MIN_FREE_BYTES, McapWriter, best_compression, check_writable

__all__ = [
           "COMPRESSIONS",
           "MAGIC",
           "MIN_FREE_BYTES",
           "AttachmentInfo",
           "ChannelInfo",
           "McapLog",
           "McapWriter",
           "best_compression",
           "check_writable",
           "read_attachment",
           "read_log",
]
