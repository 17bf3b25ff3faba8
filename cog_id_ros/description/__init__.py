"""The descriptions a mechanism is read from, into the core's native parameters.

The core (:mod:`cog_id_ros.core`) reads only the native dotted parameters and knows no file
format; this face reads the rest and hands the core its native form:

- :mod:`.mechanism`: ``cog_id_ros.Mechanism``, the core's Mechanism with
  ``from_params_file`` and ``from_parameters``, and :func:`native_form`, which tells the
  forms apart
- :mod:`.params_file`: ROS 2 parameter files, read as rcl reads them
- :mod:`.urdf`: a URDF plus loop closures (docs/urdf.md), read with :mod:`.urdf_xml` (the
  text and its XML), :mod:`.urdf_tree` (links and joints), :mod:`.loop_closures`,
  :mod:`.loop_closure_file` (the loop list of the Pinocchio ecosystem),
  :mod:`.frames` (roll-pitch-yaw) and :mod:`.rigid_bodies` (fixed joints welded)

It imports from the core, never the reverse (test/test_architecture.py).
"""
from .mechanism import Mechanism, native_form

__all__ = ['Mechanism', 'native_form']
