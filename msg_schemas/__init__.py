"""msg_schemas: the wire contracts of the fleet.

* :mod:`msg_schemas.records` - the versioned JSON records (tasks, task events, robot statuses,
  schedules, wait messages), pure Python: re-exported here, usable without ROS.
* :mod:`msg_schemas.topics` - every topic name and QoS profile (imports rclpy).
* :mod:`msg_schemas.convert` - conversions to and from ROS messages (imports the message types).

Import the last two as submodules; importing this package alone does not load ROS.
"""
from .records import (
                      RECORDS,
                      Record,
                      RecordError,
                      RobotStatus,
                      Schedule,
                      Task,
                      TaskEvent,
                      WaitMessageRecord,
                      robot_id_problem,
)

__all__ = ["RECORDS", "Record", "RecordError", "RobotStatus", "Schedule", "Task", "TaskEvent",
           "WaitMessageRecord", "robot_id_problem"]
