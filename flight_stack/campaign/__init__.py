"""Robustness campaigns: many perturbed flights flown as numpy batches (see ``docs/CAMPAIGNS.md``).

``spec`` (SPEC.yaml), ``sampling`` (flight k's conditions), ``batch`` (B flights of one controller
stepped together), ``runner`` (local processes or Dask, flights.csv streamed batch by batch),
``results`` (campaign.json), ``report`` (report.html), ``replay`` (flight k alone with its bag),
``cli`` (``run_stack.py campaign``).
"""
