"""Studies of many runs above the optimisers: optimisation runs with their FOM checks, multi-start
and Pareto sweeps, design sweeps, dry-run plans, and the caches of FOM answers they share."""
