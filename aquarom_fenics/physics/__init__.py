"""The force terms, one module each (see ``term.py``): elastic, muscle, inertia with Rayleigh damping, drag
and the Lighthill thrust (``thrust.py``, its FOM terms in ``thrust_full_order.py``, its reduced term in
``thrust_reduced.py``)."""
