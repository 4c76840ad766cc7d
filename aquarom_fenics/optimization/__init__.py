"""Cost, optimisers, dry-run plans and optimisation studies."""
