"""ROS 2 nodes: thin shells over the ROS-free pipeline (the only ROS-importing subpackage).

* ``collector_node``: ``/joint_states`` + ``/tracker/point`` -> static-pose samples on
  ``robocal/samples``, recorded to the campaign MCAP as they are taken.
* ``calibration_node``: ``robocal/samples`` -> ``robocal/calibration`` and a YAML file.
* ``uncertainty_node``: ``robocal/calibration`` (+ samples) -> Monte Carlo uncertainty on
  ``robocal/uncertainty`` and ``robocal/pose_with_covariance``.

Kept free of imports on purpose: the uncertainty node must set the BLAS thread variables
before numpy is first imported.
"""
