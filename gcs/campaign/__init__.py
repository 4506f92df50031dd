"""``gcs campaign``: the paper's experiments through the full flight stack, in parallel.

Modules, one job each:

* :mod:`gcs.campaign.plan`: the experiments, the seeded disturbances of each run (a pure
  function of campaign seed, experiment and run index: the same for every controller)
  and one :class:`~gcs.campaign.plan.Job` (a ``gcs fly --sitl lockstep`` command line)
  per flight;
* :mod:`gcs.campaign.runner`: one flight, ``gcs.cli.main(argv)`` in a worker process with
  its output in a file and a deadline; its summary read back;
* :mod:`gcs.campaign.executors`: the executor interface, a local process pool and a Dask
  backend (optional extra);
* :mod:`gcs.campaign.tables`: mean and sample standard deviation per controller, Tables
  1-5 (Markdown, JSON);
* :mod:`gcs.campaign.paper`: the paper's printed numbers;
* :mod:`gcs.campaign.trends`: the paper's trends, checked on its numbers and ours;
* :mod:`gcs.campaign.optimality`: the altitude optimality gap as campaign output;
* :mod:`gcs.campaign.figures`: PNG figures like Figs. 4-22 from the flight logs;
* :mod:`gcs.campaign.report`: RESULTS.md;
* :mod:`gcs.campaign.campaign`: the whole run and the output folder;
* :mod:`gcs.cli.campaign`: the ``gcs campaign`` subcommand.
"""

from gcs.campaign.errors import CampaignError
from gcs.campaign.plan import (
           EXPERIMENTS,
           CampaignOptions,
           DisturbanceModel,
           Job,
           Plan,
           draw_disturbances,
           plan_campaign,
)

__all__ = ["CampaignError", "EXPERIMENTS", "CampaignOptions", "DisturbanceModel", "Job", "Plan",
           "draw_disturbances", "plan_campaign"]
