"""pip install for users without ROS; colcon builds through CMakeLists.txt instead."""

from setuptools import setup

setup()
