"""The review tools behind ``gcs log``: info, metrics recomputed from a log, plot, compare, export, channels.

They read logs with :mod:`gcs.log.mcap.reader` only (truncated ones included: ``truncated``
and ``problem`` in every result) and know the messages by :mod:`gcs.log.topics`; input that
is not an MCAP log is a :class:`gcs.errors.LogError`.

* :mod:`~gcs.log.review.flights` — the flights of a log and their records and metrics;
* :mod:`~gcs.log.review.stream` — the same on a log read as a stream (``gcs log metrics``);
* :mod:`~gcs.log.review.info` — :func:`log_info`;
* :mod:`~gcs.log.review.metrics` — :func:`log_metrics`, :func:`compare_logs`;
* :mod:`~gcs.log.review.export` — :func:`export_csv`;
* :mod:`~gcs.log.review.channels` — :func:`log_channels` (topic, schema, encodings, count; the Foxglove
  well-known messages validated against the schemas in the file);
* :mod:`~gcs.log.review.plot` — :func:`~gcs.log.review.plot.plot_log` (matplotlib);
* :mod:`~gcs.log.review.cli` — the ``gcs log`` subcommands (formatting for the terminal).
"""

from gcs.log.review.channels import log_channels
from gcs.log.review.export import export_csv, flatten
from gcs.log.review.info import log_info
from gcs.log.review.metrics import compare_logs, log_metrics

__all__ = ["compare_logs", "export_csv", "flatten", "log_channels", "log_info", "log_metrics"]
