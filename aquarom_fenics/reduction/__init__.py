"""Model reduction: the basis, the projection on it, the reductor, the reduced model and its cache."""
