"""Monte Carlo campaigns: dispersed runs of a designed case on Dask, results in Parquet.

- :mod:`fahv.campaign.spec`: the campaign file (configuration language of
  :mod:`fahv.config`), validated once, errors naming the dotted key.
- :mod:`fahv.campaign.draws`: the dispersed values of run ``i``, a function of
  (campaign seed, i) only, and the node parameter overrides they become.
- :mod:`fahv.campaign.engine`: batches of runs as Dask tasks (batched simulator
  :func:`fahv.loop.batch.simulate_batch`), results written incrementally, resume.
- :mod:`fahv.campaign.store`: the Parquet dataset of a campaign folder.
- :mod:`fahv.campaign.report`: pass rates, failure-probability bounds, worst runs,
  figures.
- :mod:`fahv.campaign.rerun`: one run again, recorded as a run folder (MCAP).
"""
