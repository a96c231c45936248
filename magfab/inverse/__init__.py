"""Inverse design: from what the sensor must do (a TARGETS file) to buildable specs, searched on Dask.

One job per module, in the order a study runs:

``targets``  the TARGETS file: requirements, variables, objectives, study settings (validated, one-line errors)
``space``    a point of the search (stock disc and grade, distances, diameter, cover, tip, silicone) -> a spec
``evaluate`` one design through the model chain (the elastomer surrogate, or the full FE chain) and the checks
``study``    Optuna ask-and-tell on a Dask cluster, the store (journal file or database), resume
``pareto``   fronts, ranks, which designs the full chain re-verifies
``run``      ``magfab design`` and ``magfab sweep`` end to end
``tables``, ``page``, ``files``   CSV/Parquet tables, the Pareto plot and page, whole-or-nothing file writes
"""
