"""docs/node.md's parameter and topic tables are generated from the code's one table each
(cog_id_ros.ros.parameters, cog_id_ros.ros.topics): no ROS needed."""
import inspect
import math
import os

import pytest

from cog_id_ros import Mechanism, MechanismConfigError
from cog_id_ros.description import params_file
from cog_id_ros.ros import parameters, topics

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NODE_MD = os.path.join(REPO, 'docs', 'node.md')


@pytest.mark.parametrize('module', [parameters, topics], ids=['parameters', 'topics'])
def test_docs_table_is_the_generated_one(module):
    with open(NODE_MD, encoding='utf-8') as stream:
        text = stream.read()
    name = module.__name__
    assert parameters.generated_block(text, name) == module.markdown_table(), (
        f'docs/node.md differs from the table in the code: run '
        f'python -m {name} --write docs/node.md')


def test_every_parameter_has_a_type_a_checked_default_and_a_description():
    for name, param in parameters.NODE_PARAMETERS.items():
        assert param.name == name and param.description and param.type
        for types in (['revolute'], ['revolute', 'prismatic']):
            param.check(param.default, types)      # the default passes its own check


@pytest.mark.parametrize('name, value, message', [
    ('setpoint_timeout', 0.001, 'must be from 0.005 to 3600 s (or 0: no timeout), got 0.001'),
    ('max_stamp_lead', -1.0, 'must be from 0 to inf s (or .inf: no check), got -1.0'),
    ('estimator_window', 9, 'must be an integer from 3 to 8, got 9'),
    ('timeout_behavior', 'stop', "must be one of hold, zero, none, got 'stop'"),
    ('unwrap_angles', 1, 'must be true or false, got 1'),
    ('effort_limits', [1.0, 2.0, 3.0], 'needs one limit per active joint (2) or one for all, got 3'),
    ('max_setpoint_step', [0.0], 'every step must be > 0 (.inf for none), got [0.0, 0.0]'),
    ('diagnostics_period', 'x', "must be a number, got 'x'"),
])
def test_checks_name_the_parameter(name, value, message):
    with pytest.raises(MechanismConfigError) as error:
        parameters.NODE_PARAMETERS[name].check(value, ['revolute', 'prismatic'])
    assert error.value.parameter == name
    assert message in str(error.value)


def test_special_values_and_per_joint_defaults():
    nodes = parameters.NODE_PARAMETERS
    assert nodes['setpoint_timeout'].check(0, ['revolute']) == 0.0
    assert nodes['max_stamp_lead'].check(math.inf, ['revolute']) == math.inf
    assert nodes['max_setpoint_step'].check([], ['revolute', 'prismatic']).tolist() == [1.0, 0.1]
    assert nodes['effort_limits'].check(None, ['revolute']).tolist() == [math.inf]
    assert nodes['effort_limits'].check(2, ['revolute', 'revolute']).tolist() == [2.0, 2.0]


def test_one_default_node_name():
    from cog_id_ros.ros.node import NODE_NAME
    default = inspect.signature(Mechanism.from_params_file).parameters['node_name'].default
    assert default == params_file.DEFAULT_NODE_NAME == NODE_NAME


def test_topic_table_names_the_node_topics():
    assert list(topics.TOPICS) == ['joint_setpoint', 'joint_trajectory', 'effort_command',
                                   'joint_effort', 'joint_states', 'effort_trajectory',
                                   '/diagnostics']
