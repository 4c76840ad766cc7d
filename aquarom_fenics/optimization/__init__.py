"""The cost, the optimisers (paper method, trust region), their history and PROM builder; the
studies of many runs above them are in :mod:`aquarom_fenics.studies`."""
