"""Design search of the carrier (the paper's "parametric optimization under stick-slip
conditions"): the design space (:mod:`.space`), the stick-slip conditions of set S
(:mod:`.stick_slip_conditions`), the global optimiser (:mod:`.optimizer`) and the sensitivity
table at the optimum (:mod:`.sensitivity`). ROS-free; ``feeder design`` is the command."""
