"""``cog_id_ros.Mechanism``: the core's Mechanism, made from what users write.

The core's Mechanism (:mod:`cog_id_ros.core.model.mechanism`) is made from the native dotted
parameters and knows no file format. This module adds the two ways users make one
(docs/parameter_file.md, docs/mechanism.md, docs/urdf.md):
:meth:`Mechanism.from_params_file` (a ROS 2 parameter file, :mod:`.params_file`) and
:meth:`Mechanism.from_parameters` (a dict, native or in the URDF form, :mod:`.urdf`),
which turn what they are given into the native parameters (:func:`native_form`) and hand
them to the core.

Why a subclass, rather than a hook this face would install into the core at import: the
core stays whole on its own (importable, typed and tested without this face), nothing is
installed into it from above, and neither an import nor a call runs from the core up to
the readers. A URDF's loop-closure file (:mod:`.loop_closure_file`) is read with its URDF.
Everything else is the core's, unchanged: an instance is a
core Mechanism (``InverseDynamics`` takes it) with the core's repr, error messages and
read-only attributes; it pickles by this class's path (across processes the node sends
``mechanism.parameters``, a dict, never a Mechanism). The forms the core makes for itself
(``solver_mechanism``, when chains of three revolutes stand for spherical joints) are core
Mechanisms: nothing reads them from a file.
"""
import os

from ..core.errors import MechanismConfigError
from ..core.kinematics.parameters import ParameterReader
from ..core.model import mechanism as core
from . import urdf
from .params_file import DEFAULT_NODE_NAME, load_params_file
from .urdf_messages import for_urdf_user


def native_form(params: dict, base_dir: 'str | dict | None' = None) -> dict:
    """The native parameters of ``params`` (dotted names, as rclpy gives them, or a nested
    dict): ``params`` itself when it is in the native form; read into it when it is in the
    URDF form (``robot_description`` or ``mechanism.urdf_file`` with loop closures,
    docs/urdf.md), a relative ``mechanism.urdf_file`` or ``mechanism.loop_closure_file``
    looked for in ``base_dir`` (default: the working directory; a dict: the directory of
    each). MechanismConfigError naming the parameter."""
    if not isinstance(params, dict):
        raise MechanismConfigError('parameters', f'must be a dict, got {type(params).__name__}')
    flat = ParameterReader(params).params
    if urdf.is_urdf(flat):
        return urdf.native_parameters(flat, base_dir)
    if 'mechanism.loop_closure_file' in flat:
        raise MechanismConfigError(
            'mechanism.loop_closure_file', 'lists the loops of a URDF: give the URDF too '
                                           '(robot_description or mechanism.urdf_file)')
    return params


class Mechanism(core.Mechanism):
    """Links, joints and actuators of a (closed-link) mechanism, read from a parameter file
    or parameters (docs/mechanism.md); the core's Mechanism with its two readers."""

    @classmethod
    def from_parameters(cls, params: dict, base_dir: 'str | dict | None' = None
                        ) -> 'Mechanism':
        """From a dict of dotted parameter names (as rclpy gives them) or a nested dict.

        A URDF form (``robot_description`` or ``mechanism.urdf_file`` with loop closures,
        docs/urdf.md) is first turned into the native form by :mod:`cog_id_ros.description.urdf`
        (file formats live outside the core); ``base_dir`` is where a relative
        ``mechanism.urdf_file`` or ``mechanism.loop_closure_file`` is looked for (default:
        the working directory; a dict: the directory of each)."""
        if not isinstance(params, dict) or not urdf.is_urdf(ParameterReader(params).params):
            return cls(native_form(params, base_dir))
        native, sources = urdf.read(params, base_dir)
        try:
            return cls(native)
        except MechanismConfigError as exc:     # said in the terms of the URDF form
            raise for_urdf_user(exc, native, sources) from None

    @classmethod
    def from_params_file(cls, path: 'str | os.PathLike', node_name: str = DEFAULT_NODE_NAME
                         ) -> 'Mechanism':
        """From a ROS 2 parameter file (node entry ``node_name`` or ``/**``).

        The file is read by :mod:`cog_id_ros.description.params_file` (the ROS conventions
        live outside the core); ``node_name`` is the node's name, ``cog_id_node`` (a test
        checks it is the node's NODE_NAME). A relative ``mechanism.urdf_file`` or
        ``mechanism.loop_closure_file`` is relative to the file's directory."""
        return cls.from_parameters(load_params_file(path, node_name),
                                   base_dir=os.path.dirname(os.path.abspath(path)))
