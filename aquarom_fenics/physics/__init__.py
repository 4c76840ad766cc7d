"""The force terms, one module each (see ``term.py``): elastic, muscle, inertia with Rayleigh damping, drag
and the Lighthill thrust (``thrust.py``, its full and reduced term in ``thrust_term.py``)."""
