"""Monte Carlo campaigns on Dask distributed: uncertainty models of the report's models, run by the thousand.

``campaign`` (the spec: model, experiments, dispersions, metrics), ``dispersions`` (targets from the
parameter metadata; each run's values from (seed, run index)), ``metrics``, ``runs`` (a block of runs in one
compiled call, what a worker executes), ``ail`` (aircraft-in-the-loop runs), ``engine`` (Dask: a local
cluster or any scheduler), ``output`` (Parquet parts, manifest, summary), ``summary``, ``plots``,
``builtin`` (the report's campaigns and their cross-checks), ``campaigns`` (running one end to end).
"""

from ema_sim.montecarlo.builtin import BUILTIN, builtin_campaign
from ema_sim.montecarlo.campaign import Campaign, parse_campaign, read_campaign
from ema_sim.montecarlo.campaigns import load_campaign, run_campaign

__all__ = ["BUILTIN", "Campaign", "builtin_campaign", "load_campaign", "parse_campaign", "read_campaign",
           "run_campaign"]
