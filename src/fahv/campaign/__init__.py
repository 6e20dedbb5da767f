"""Monte Carlo campaigns: dispersed runs of a designed case on Dask, results in Parquet.

- `fahv.campaign.spec`: the campaign file (configuration language of
  `fahv.config`), validated once, errors naming the dotted key.
- `fahv.campaign.draws`: the dispersed values of run `i`, a function of
  (campaign seed, i) only, and the node parameter overrides they become.
- `fahv.campaign.engine`: batches of runs as Dask tasks (batched simulator
  `fahv.loop.batch.simulate_batch`), results written incrementally, resume.
- `fahv.campaign.store`: the Parquet dataset of a campaign folder.
- `fahv.campaign.report`: pass rates, failure-probability bounds, worst runs;
  `fahv.campaign.figures`: its figures; `fahv.campaign.paired`: the paired comparison.
- `fahv.campaign.rerun`: one run again, recorded as a run folder (MCAP).
- `fahv.campaign.robustness`: each requirement's margin on a run, continued past a
  failure (the clearance search minimises it); `fahv.campaign.attribution`: which
  dispersed values drive each margin and its failures.
"""
