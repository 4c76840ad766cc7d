"""Physics that is not a UFL form: the Lighthill thrust on the spine."""
