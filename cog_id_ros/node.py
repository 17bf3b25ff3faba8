"""``python -m cog_id_ros.node``: cog_id_node, whose main is :mod:`cog_id_ros.ros.main`.

Kept so that the command of the design contract and of existing launch scripts works::

    python -m cog_id_ros.node --ros-args --params-file config/paper_four_bar_a.yaml
"""
import sys

from .ros.main import main

__all__ = ['main']

if __name__ == '__main__':
    sys.exit(main())
