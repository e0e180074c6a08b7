"""Processing takes on a Dask cluster: frame sets as tasks, outputs on shared storage."""
