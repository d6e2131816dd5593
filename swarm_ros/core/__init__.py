"""The ROS-free core of swarm_ros: world, shapes, robot rule, arbitration, metrics, engine.

Nothing here imports rclpy, ROS message packages or rerun; the ROS 2 nodes and the
recorder convert to and from these types at their edges.
"""

from .arbitration import JoinOutcome
from .engine import Simulation
from .errors import ParameterError, ShapeError, SwarmError
from .metrics import METRIC_COLUMNS, Outcome, TickMetrics
from .params import RunParams
from .rules import Decisions, decide
from .shapes import Shape, builtin_shapes
from .state import RobotState, SwarmState
from .world import World

__all__ = [
    "Decisions", "JoinOutcome", "METRIC_COLUMNS", "Outcome", "ParameterError", "RobotState", "RunParams",
    "Shape", "ShapeError", "Simulation", "SwarmError", "SwarmState", "TickMetrics", "World", "builtin_shapes",
    "decide",
]
