"""robocal_uncertainty: robot arm calibration and its Monte Carlo uncertainty (JCGM 101).

Kept trivial on purpose: in a colcon build, rosidl generates the package's top-level
``__init__.py`` beside the ``msg`` module, so nothing may rely on code here.
"""
