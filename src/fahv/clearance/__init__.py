"""Clearance: a search of a campaign's dispersion space for each requirement's worst case.

A Monte Carlo campaign says how often a requirement fails; a clearance asks what the
worst case inside the uncertainty set is, and whether it is still acceptable (GARTEUR
FM-AG11; Varga, Hansson, Puyou (eds.), *Optimization Based Clearance of Flight Control
Laws*, Springer LNCIS 2012). The search runs a well-kept global optimiser (CMA-ES, or
scipy's differential evolution) over the campaign's dispersions (`space`), each generation one
batch of the campaign engine (`evaluate`), on a continuous robustness value of each
requirement (`fahv.campaign.robustness`), within a budget of simulations (`search`).

- `fahv.clearance.space`: the campaign's dispersions as a box, a point's run values.
- `fahv.clearance.search`: CMA-ES and differential evolution within a budget.
- `fahv.clearance.evaluate`: a generation's runs as campaign-engine tasks on Dask.
- `fahv.clearance.worst`: a worst case as a scenario file.
- `fahv.clearance.report`: the folder's table, Markdown and figures, beside a campaign's.
- `fahv.clearance.run`: `fahv clearance`'s search per requirement and its folder.
"""
