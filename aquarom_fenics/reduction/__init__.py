"""Model reduction: the basis, the reductor, the reduced model and its cache."""
