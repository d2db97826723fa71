"""Robot descriptions: URDF files shipped with the package and the loader.

``load_robot("paper6")`` loads a shipped robot; ``load_robot("path/to/robot.urdf")`` loads a
user's. The URDF's root link is the satellite base; its ``<inertial>`` is the base with a full tank.
"""

from __future__ import annotations

from spaceid_gym.robots.robot import Robot, available_robots, load_robot, robot_from_urdf_text

__all__ = ["Robot", "available_robots", "load_robot", "robot_from_urdf_text"]
