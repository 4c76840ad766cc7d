"""Many independent runs: a ``concurrent.futures``-shaped pool of workers (in this process, local
processes or a Dask cluster) and the cluster settings; nothing here knows what the tasks compute."""
