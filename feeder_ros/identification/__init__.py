"""System identification of the feeder's speed response (paper Section 4, Eqs. 21-25): ROS-free.

:mod:`~feeder_ros.identification.rational_fit` fits a rational transfer function G(s) (Eq. 22)
to a speed sweep (mean part speed per drive frequency, a magnitude without phase) by the
weighted least squares of Eq. 23, and chooses the model order on held-out frequencies;
:mod:`~feeder_ros.identification.speed_model_file` stores the identified models as YAML and turns
them into the speed table the drive interface's target-speed mode uses. Import from the modules:
this package module imports nothing, so that a light module of it does not pull in SciPy.
"""
